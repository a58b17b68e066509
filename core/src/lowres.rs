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
//! Integer arithmetic only; no allocation (stack chunks of a few KiB); the
//! caller provides every buffer. Both full-frame loops are slice-wise and
//! vectorise: the downsample is about half an instruction per source pixel
//! (default 4 × 4 blocks, read as 32-bit words), the
//! gradient (decomposed by row half-width, see [`gradient_disk_u16`]) a
//! few per low-resolution pixel (README "Performance").

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

/// Output columns per chunk of [`box_mean16`] and [`gradient_disk_u16`]
/// (stack buffers; no allocation).
const CHUNK: usize = 256;

/// Downsamples `src` by `f` into the packed `dst` (`⌈w/f⌉ × ⌈h/f⌉`):
/// each output pixel is `round(16 · Σ/count)` over its `f × f` block
/// (rounding half up, exact in integers). Returns the output size.
///
/// Cost: per output row the `f` source rows are summed column-wise into a
/// `u32` chunk (one vectorised add per source pixel), then each block's
/// `f` column sums are added and scaled once per output pixel.
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
    // source columns per chunk: a whole number of blocks (f ≤ CHUNK), or
    // one block per chunk for larger factors
    let span = if f <= CHUNK { (CHUNK / f) * f } else { f };
    let mut cols = [0u16; CHUNK];
    for (ly, drow) in dst.chunks_exact_mut(lw.max(1)).enumerate().take(lh) {
        let y0 = ly * f;
        let y1 = (y0 + f).min(h);
        let rows = (y1 - y0) as u64;
        if f == 4 && rows == 4 && blocks4_row(src, y0, drow) {
            continue;
        }
        let mut x0 = 0usize;
        while x0 < w {
            let x1 = (x0 + span).min(w);
            if f <= CHUNK {
                // column sums ≤ 255 · f ≤ 65280 fit a u16
                let cols = &mut cols[..x1 - x0];
                column_sums(src, y0, y1, x0, cols);
                let out = drow.get_mut(x0 / f..).unwrap_or(&mut []);
                if f == 4 && rows == 4 {
                    // the default: (16 s + 8) / 16 = s, s ≤ 4080
                    for (o, blk) in out.iter_mut().zip(cols.chunks_exact(4)) {
                        *o = blk[0] + blk[1] + blk[2] + blk[3];
                    }
                    let tail = cols.chunks_exact(4).remainder();
                    if !tail.is_empty() {
                        if let Some(o) = out.get_mut(cols.len() / 4) {
                            let s: u32 = tail.iter().map(|&c| c as u32).sum();
                            *o = mean16(s as u64, tail.len() as u64 * rows);
                        }
                    }
                } else {
                    for (o, blk) in out.iter_mut().zip(cols.chunks(f)) {
                        let s: u32 = blk.iter().map(|&c| c as u32).sum();
                        *o = mean16(s as u64, blk.len() as u64 * rows);
                    }
                }
            } else {
                // one block wider than a chunk: sum it row by row
                let mut s = 0u64;
                for y in y0..y1 {
                    let part = src.row(y).get(x0..x1).unwrap_or(&[]);
                    s += part.iter().map(|&p| p as u64).sum::<u64>();
                }
                if let Some(d) = drow.get_mut(x0 / f) {
                    *d = mean16(s, (x1 - x0) as u64 * rows);
                }
            }
            x0 = x1;
        }
    }
    Ok((lw, lh))
}

/// The default 4 × 4 blocks of rows `y0..y0 + 4` into `out` (`16 · mean =
/// Σ`), when the width is a multiple of 4 and the four rows can be read
/// as 32-bit words (one word = one block row); `false` (nothing written)
/// otherwise. Per word, the pixel pairs are summed in two 16-bit halves
/// (`(w & 0x00FF00FF) + ((w >> 8) & 0x00FF00FF)`, ≤ 2040 after four rows)
/// and the halves added at the end: a few vector instructions per block,
/// whatever the byte order.
fn blocks4_row(src: ImageView<'_>, y0: usize, out: &mut [u16]) -> bool {
    let w = src.width();
    if w % 4 != 0 || y0 + 4 > src.height() || out.len() < w / 4 {
        return false;
    }
    let word_row =
        |y: usize| -> Option<&[u32]> { bytemuck::try_cast_slice(src.row(y).get(..w)?).ok() };
    let (Some(a), Some(b), Some(c), Some(d)) = (
        word_row(y0),
        word_row(y0 + 1),
        word_row(y0 + 2),
        word_row(y0 + 3),
    ) else {
        return false;
    };
    const M: u32 = 0x00FF_00FF;
    let pairs = |v: u32| (v & M) + ((v >> 8) & M);
    for ((((o, &a), &b), &c), &d) in out.iter_mut().zip(a).zip(b).zip(c).zip(d) {
        let p = (pairs(a) + pairs(b)) + (pairs(c) + pairs(d));
        *o = ((p & 0xFFFF) + (p >> 16)) as u16;
    }
    true
}

/// `cols[i] = Σ_{y0 ≤ y < y1} src(x0 + i, y)`, four rows per pass (each
/// pass a handful of vector instructions per 16 columns). Sums must fit a
/// `u16` (`y1 − y0 ≤ 257`).
fn column_sums(src: ImageView<'_>, y0: usize, y1: usize, x0: usize, cols: &mut [u16]) {
    let x1 = x0 + cols.len();
    cols.fill(0);
    let part = |y: usize| src.row(y).get(x0..x1).unwrap_or(&[]);
    let mut y = y0;
    while y + 4 <= y1 {
        let (a, b, c, d) = (part(y), part(y + 1), part(y + 2), part(y + 3));
        for ((((s, &a), &b), &c), &d) in cols.iter_mut().zip(a).zip(b).zip(c).zip(d) {
            *s += (a as u16 + b as u16) + (c as u16 + d as u16);
        }
        y += 4;
    }
    while y < y1 {
        for (s, &a) in cols.iter_mut().zip(part(y)) {
            *s += a as u16;
        }
        y += 1;
    }
}

/// `round(16 · s / count)` rounding half up, saturated to `u16`; 0 for an
/// empty block.
#[inline]
fn mean16(s: u64, count: u64) -> u16 {
    let v = if count == 16 {
        // the default 4 × 4 block: (16 s + 8) / 16 = s
        s
    } else {
        (16 * s + count / 2).checked_div(count).unwrap_or(0)
    };
    v.min(u16::MAX as u64) as u16
}

/// Grey morphological gradient of the packed `u16` image `src`
/// (`width × height`) by `disk` into `dst`: per pixel the maximum minus
/// the minimum over the element's pixels that lie inside the image.
///
/// Decomposed by half-width: the element is the union over its distinct
/// row half-widths `t` of (rows with half-width ≥ `t`) × `[−t, t]`, so the
/// rows are merged into one vertical extremum in order of decreasing
/// half-width and, after each distinct `t`, that extremum's horizontal
/// window `[−t, t]` is merged into the output. For the 5 × 5 disk that is
/// 11 maxima (and 11 minima) per pixel instead of 21, all slice-wise over
/// chunks of `CHUNK` columns padded with the identity outside the image
/// (which is how outside pixels are ignored).
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
    const R: usize = crate::morph::MAX_SE / 2;
    let r = disk.radius.min(R);
    // half-width of row dy (clamped to r: the element spans −r..=r)
    let hw = |dy: isize| disk.half_width(dy).min(r);
    // values are compared as i16 after flipping the top bit (an
    // order-preserving map of u16 onto i16): baseline SSE2 has signed
    // 16-bit max/min but not unsigned ones; max − min is unchanged
    const FLIP: u16 = 0x8000;
    let mut vmax = [i16::MIN; CHUNK + 2 * R];
    let mut vmin = [i16::MAX; CHUNK + 2 * R];
    let mut amax = [i16::MIN; CHUNK];
    let mut amin = [i16::MAX; CHUNK];
    for (y, drow) in dst.chunks_exact_mut(width.max(1)).enumerate().take(height) {
        let mut x0 = 0usize;
        while x0 < width {
            let x1 = (x0 + CHUNK).min(width);
            let m = x1 - x0;
            // v[i] holds column x0 − r + i, i in 0..m + 2r
            let (vmax, vmin) = (&mut vmax[..m + 2 * r], &mut vmin[..m + 2 * r]);
            let (amax, amin) = (&mut amax[..m], &mut amin[..m]);
            // columns of the chunk's padded span that lie inside the image
            let ca = x0.saturating_sub(r);
            let cb = (x1 + r).min(width);
            let off = ca + r - x0; // index in v of column ca
                                   // the padding outside the image holds the identities
            vmax[..off].fill(i16::MIN);
            vmin[..off].fill(i16::MAX);
            vmax[off + (cb - ca)..].fill(i16::MIN);
            vmin[off + (cb - ca)..].fill(i16::MAX);
            let (mut v_started, mut a_started) = (false, false);
            for t in (0..=r).rev() {
                let mut added = false;
                for dy in -(r as isize)..=(r as isize) {
                    let yy = y as isize + dy;
                    if hw(dy) != t || yy < 0 || yy >= height as isize {
                        continue;
                    }
                    let s = yy as usize * width;
                    if let (Some(row), Some(vx), Some(vn)) = (
                        src.get(s + ca..s + cb),
                        vmax.get_mut(off..off + (cb - ca)),
                        vmin.get_mut(off..off + (cb - ca)),
                    ) {
                        if v_started {
                            for ((a, b), &p) in vx.iter_mut().zip(vn.iter_mut()).zip(row) {
                                let p = (p ^ FLIP) as i16;
                                *a = (*a).max(p);
                                *b = (*b).min(p);
                            }
                        } else {
                            for ((a, b), &p) in vx.iter_mut().zip(vn.iter_mut()).zip(row) {
                                let p = (p ^ FLIP) as i16;
                                *a = p;
                                *b = p;
                            }
                            v_started = true;
                        }
                        added = true;
                    }
                }
                if !added {
                    continue;
                }
                // output i covers v[i + r − t ..= i + r + t]
                for k in r - t..=r + t {
                    if let (Some(vx), Some(vn)) = (vmax.get(k..k + m), vmin.get(k..k + m)) {
                        if a_started {
                            for (((a, b), &p), &q) in
                                amax.iter_mut().zip(amin.iter_mut()).zip(vx).zip(vn)
                            {
                                *a = (*a).max(p);
                                *b = (*b).min(q);
                            }
                        } else {
                            amax.copy_from_slice(vx);
                            amin.copy_from_slice(vn);
                            a_started = true;
                        }
                    }
                }
            }
            if let Some(d) = drow.get_mut(x0..x1) {
                if a_started {
                    for ((o, &a), &b) in d.iter_mut().zip(amax.iter()).zip(amin.iter()) {
                        *o = (a as u16).wrapping_sub(b as u16);
                    }
                } else {
                    d.fill(0);
                }
            }
            x0 = x1;
        }
    }
    Ok(())
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
    // (counts cannot wrap: fewer than 2³² values reach one bin for any
    // frame a u16 run can describe)
    let last = bins - 1;
    // eight values per step (unrolled: no loop overhead per increment)
    let mut it = values.chunks_exact(8);
    for c8 in &mut it {
        for &v in c8 {
            let c = &mut hist[(v as usize).min(last)];
            *c = c.wrapping_add(1);
        }
    }
    for &v in it.remainder() {
        let c = &mut hist[(v as usize).min(last)];
        *c = c.wrapping_add(1);
    }
    let (med, mad) = crate::hist::median_mad(hist, dev);
    (med as u32, mad as u32)
}

#[cfg(test)]
pub(crate) mod tests {
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

    /// xorshift pixels of `w × h`, each the top bits of the state above `shift`.
    pub(crate) fn pixels(w: usize, h: usize, seed: u64, shift: u32) -> Vec<u64> {
        let mut s = seed | 1;
        (0..w * h)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                s >> shift
            })
            .collect()
    }

    fn check_mean16(w: usize, h: usize, f: usize, seed: u64) -> Result<(), TestCaseError> {
        let img: Vec<u8> = pixels(w, h, seed, 24)
            .into_iter()
            .map(|p| p as u8)
            .collect();
        let want = naive_mean16(&img, w, h, f);
        // at every byte offset: the word-wise 4 × 4 path needs aligned rows
        for off in 0..4 {
            let mut buf = vec![0u8; off];
            buf.extend_from_slice(&img);
            let v = ImageView::packed(&buf[off..], w, h).unwrap();
            let (lw, lh) = low_size(w, h, f);
            let mut out = vec![0u16; lw * lh];
            prop_assert_eq!(box_mean16(v, f, &mut out), Ok((lw, lh)));
            prop_assert_eq!(&out, &want);
        }
        Ok(())
    }

    fn check_gradient(
        w: usize,
        h: usize,
        size: u8,
        seed: u64,
        shift: u32,
    ) -> Result<(), TestCaseError> {
        let img: Vec<u16> = pixels(w, h, seed, shift)
            .into_iter()
            .map(|p| p as u16)
            .collect();
        let disk = Disk::opencv_ellipse(2 * size + 1);
        let mut out = vec![0u16; w * h];
        prop_assert_eq!(gradient_disk_u16(&img, w, h, &disk, &mut out), Ok(()));
        prop_assert_eq!(out, naive_gradient(&img, w, h, &disk));
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 64 }))]
        #[test]
        fn mean16_equals_naive(w in 1usize..70, h in 1usize..20, f in 1usize..9,
                               seed in any::<u64>()) {
            check_mean16(w, h, f, seed)?;
        }

        #[test]
        fn gradient_equals_naive(w in 1usize..30, h in 1usize..30, size in 0u8..4,
                                 seed in any::<u64>()) {
            check_gradient(w, h, size, seed, 52)?;
        }

        /// Across several column chunks, and factors above the chunk.
        #[test]
        fn wide_mean16_equals_naive(w in 200usize..700, h in 1usize..6,
                                    f in prop::sample::select(vec![1usize, 3, 4, 5, 16, 300]),
                                    seed in any::<u64>()) {
            check_mean16(w, h, f, seed)?;
        }

        /// Across several column chunks, with disks up to 9 × 9.
        #[test]
        fn wide_gradient_equals_naive(w in 200usize..600, h in 1usize..10, size in 0u8..5,
                                      seed in any::<u64>()) {
            check_gradient(w, h, size, seed, 48)?;
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
