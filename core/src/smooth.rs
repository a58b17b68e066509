//! `k × k` box mean of a frame over one region of interest (beyond the
//! paper; used by the local segmentation, `crate::segment::local`, when
//! `Params::local_smooth > 1`).
//!
//! Definition: `S(x, y) = round(Σ_{|dx|,|dy| ≤ r} I(clamp(x+dx), clamp(y+dy)) / k²)`
//! with `r = (k − 1) / 2`, coordinates clamped to the *frame* (replicated
//! border, `cv2.BORDER_REPLICATE`), so a region's smoothed pixels are the
//! same as those of the whole smoothed frame, and halves rounded up.
//!
//! Cost: running column sums slid down the region and a running row sum —
//! four additions and one multiply-shift per pixel, whatever `k`. The
//! division by `k²` is exact integer arithmetic: for `n < 2³²/k²`,
//! `⌊n/d⌋ = (n · ⌈2³²/d⌉) >> 32` (here `n ≤ 225 · 255 + 112`).

use crate::image::{ImageView, Roi};

/// Why a box mean could not be computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SmoothError {
    /// `k` is even, 0, or above 15.
    BadSize,
    /// The region is empty or not inside the frame.
    BadRoi,
    /// `colsum` is shorter than `roi.w + k − 1` or `out` than the region.
    BufferTooSmall,
}

/// Largest supported box side.
pub const MAX_SMOOTH: u8 = 15;

/// Writes the `k × k` box mean of `frame` over `roi` into `out` (packed,
/// `roi.w` wide). `colsum` is scratch of at least `roi.w + k − 1` words.
/// `k = 1` copies the pixels.
pub fn box_mean_roi(
    frame: ImageView<'_>,
    roi: Roi,
    k: u8,
    colsum: &mut [u32],
    out: &mut [u8],
) -> Result<(), SmoothError> {
    if k % 2 == 0 || k > MAX_SMOOTH {
        return Err(SmoothError::BadSize);
    }
    let (fw, fh) = (frame.width(), frame.height());
    if roi.is_empty() || roi.right() as usize > fw || roi.bottom() as usize > fh {
        return Err(SmoothError::BadRoi);
    }
    let (rw, rh) = (roi.w as usize, roi.h as usize);
    let r = (k / 2) as usize;
    let cw = rw + 2 * r;
    let colsum = colsum.get_mut(..cw).ok_or(SmoothError::BufferTooSmall)?;
    let out = out.get_mut(..rw * rh).ok_or(SmoothError::BufferTooSmall)?;
    let (x0, y0) = (roi.x as usize, roi.y as usize);
    if k == 1 {
        for (j, orow) in out.chunks_exact_mut(rw).enumerate() {
            if let Some(src) = frame.row(y0 + j).get(x0..x0 + rw) {
                orow.copy_from_slice(src);
            }
        }
        return Ok(());
    }
    // frame column of halo column i (replicated border)
    let col = |i: usize| (x0 + i).saturating_sub(r).min(fw - 1);
    let row_of = |y: isize| -> &[u8] { frame.row(y.clamp(0, fh as isize - 1) as usize) };
    // column sums over rows y0 − r ..= y0 + r
    colsum.fill(0);
    for dy in -(r as isize)..=(r as isize) {
        let row = row_of(y0 as isize + dy);
        for (i, c) in colsum.iter_mut().enumerate() {
            *c += row.get(col(i)).copied().unwrap_or(0) as u32;
        }
    }
    let d = (k as u64) * (k as u64);
    let m = (1u64 << 32).div_ceil(d);
    let half = (d / 2) as u32;
    for (j, orow) in out.chunks_exact_mut(rw).enumerate() {
        if j > 0 {
            let y = (y0 + j) as isize;
            let add = row_of(y + r as isize);
            let sub = row_of(y - r as isize - 1);
            for (i, c) in colsum.iter_mut().enumerate() {
                let ci = col(i);
                *c = *c + add.get(ci).copied().unwrap_or(0) as u32
                    - sub.get(ci).copied().unwrap_or(0) as u32;
            }
        }
        let mut acc: u32 = colsum.get(..k as usize).map_or(0, |c| c.iter().sum());
        for (i, o) in orow.iter_mut().enumerate() {
            *o = (((acc + half) as u64 * m) >> 32) as u8;
            if let (Some(&a), Some(&s)) = (colsum.get(i + k as usize), colsum.get(i)) {
                acc = acc + a - s;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn naive(img: &[u8], w: usize, h: usize, roi: Roi, k: usize) -> Vec<u8> {
        let r = (k / 2) as isize;
        let mut out = Vec::new();
        for y in roi.y as isize..roi.bottom() as isize {
            for x in roi.x as isize..roi.right() as isize {
                let mut s = 0u32;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let xx = (x + dx).clamp(0, w as isize - 1) as usize;
                        let yy = (y + dy).clamp(0, h as isize - 1) as usize;
                        s += img[yy * w + xx] as u32;
                    }
                }
                let d = (k * k) as f64;
                out.push((s as f64 / d + 0.5).floor() as u8);
            }
        }
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 200 }))]
        #[test]
        fn equals_naive_box_mean(
            w in 1usize..40, h in 1usize..40,
            seed in any::<u64>(), kk in 0u8..8,
            rx in 0u32..40, ry in 0u32..40, rw in 1u32..40, rh in 1u32..40,
        ) {
            let k = 2 * kk + 1;
            let mut s = seed | 1;
            let img: Vec<u8> = (0..w * h).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 24) as u8
            }).collect();
            let view = ImageView::packed(&img, w, h).unwrap();
            let rx = rx % w as u32;
            let ry = ry % h as u32;
            let roi = Roi::new(rx, ry, rw.min(w as u32 - rx), rh.min(h as u32 - ry));
            let mut col = vec![0u32; roi.w as usize + k as usize];
            let mut out = vec![0u8; roi.area() as usize];
            box_mean_roi(view, roi, k, &mut col, &mut out).unwrap();
            prop_assert_eq!(out, naive(&img, w, h, roi, k as usize));
        }
    }

    #[test]
    fn bad_inputs_are_errors_not_panics() {
        let img = [7u8; 16];
        let v = ImageView::packed(&img, 4, 4).unwrap();
        let mut col = [0u32; 32];
        let mut out = [0u8; 16];
        assert_eq!(
            box_mean_roi(v, Roi::new(0, 0, 4, 4), 4, &mut col, &mut out),
            Err(SmoothError::BadSize)
        );
        assert_eq!(
            box_mean_roi(v, Roi::new(2, 2, 4, 4), 3, &mut col, &mut out),
            Err(SmoothError::BadRoi)
        );
        assert_eq!(
            box_mean_roi(v, Roi::new(0, 0, 4, 4), 3, &mut col[..5], &mut out),
            Err(SmoothError::BufferTooSmall)
        );
        box_mean_roi(v, Roi::new(0, 0, 4, 4), 15, &mut col, &mut out).unwrap();
        assert_eq!(out, [7u8; 16]);
    }
}
