//! Fixed-point bilinear remap through a lookup table: the undistort-rectify
//! preprocessing of paper Section IV.A in a form the device runs (DESIGN.md
//! "Input": frames are raw, the rectification maps are built on the host).
//!
//! The table is OpenCV's `CV_16SC2` + `CV_16UC1` map representation with
//! `INTER_BITS = 5`: per output pixel an integer source coordinate
//! `(sx, sy)` (two `i16`) and the fractions `fy·32 + fx` (one `u16`, 5 bits
//! each). The value is `Σ p·w >> 10` with integer weights
//! `(32 − fx)(32 − fy)`, `fx(32 − fy)`, `(32 − fx)fy`, `fx·fy` (sum 1024)
//! and rounding, which is bit-identical to OpenCV's 8-bit `INTER_LINEAR`
//! (weights scaled to 2¹⁵). Neighbours outside the source image read as 0
//! (OpenCV `BORDER_CONSTANT`, border value 0).
//!
//! Memory bound: none of its own; the table (`6` bytes per output pixel)
//! and both images are caller-provided slices. Never panics.

use core::fmt;

use crate::error::ImageError;
use crate::image::{ImageView, ImageViewMut};

/// Fraction bits per coordinate.
pub const INTER_BITS: u32 = 5;
/// Sub-pixel steps per pixel (`2^INTER_BITS`).
pub const INTER_TAB_SIZE: i32 = 1 << INTER_BITS;
/// Source coordinate that is outside every image (used for NaN maps).
pub const OUTSIDE: i16 = i16::MIN;

/// Why a remap was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum RemapError {
    /// The table slices do not hold `width × height` entries
    /// (`xy`: 2 per pixel, `frac`: 1 per pixel).
    TableSize {
        /// Entries needed in `xy` (2 per pixel).
        needed_xy: usize,
        /// Entries given in `xy`.
        got_xy: usize,
        /// Entries given in `frac` (1 per pixel needed).
        got_frac: usize,
    },
    /// The destination image is not the table's size.
    SizeMismatch,
    /// An image view was invalid.
    Image(ImageError),
}

impl fmt::Display for RemapError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RemapError::TableSize {
                needed_xy,
                got_xy,
                got_frac,
            } => write!(
                f,
                "remap table too small: xy has {got_xy} of {needed_xy} entries, frac has {got_frac} of {}",
                needed_xy / 2
            ),
            RemapError::SizeMismatch => write!(f, "image size differs from the remap table size"),
            RemapError::Image(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for RemapError {}

const fn sat(v: i32) -> i16 {
    if v < i16::MIN as i32 {
        i16::MIN
    } else if v > i16::MAX as i32 {
        i16::MAX
    } else {
        v as i16
    }
}

/// Packs a source coordinate given in 1/32 pixel (`round(x·32)`,
/// `round(y·32)`) into the table form: integer parts saturated to `i16`,
/// fractions `fy·32 + fx`.
pub const fn pack(xq: i32, yq: i32) -> ([i16; 2], u16) {
    let ix = xq >> INTER_BITS;
    let iy = yq >> INTER_BITS;
    let mask = INTER_TAB_SIZE - 1;
    (
        [sat(ix), sat(iy)],
        (((yq & mask) * INTER_TAB_SIZE) + (xq & mask)) as u16,
    )
}

/// Table entries a `width × height` output needs: `(xy, frac)` lengths.
pub const fn table_len(width: usize, height: usize) -> Option<(usize, usize)> {
    match width.checked_mul(height) {
        Some(n) => match n.checked_mul(2) {
            Some(n2) => Some((n2, n)),
            None => None,
        },
        None => None,
    }
}

/// A borrowed remap table for a `width × height` output image.
#[derive(Debug, Clone, Copy)]
pub struct RemapTable<'a> {
    width: usize,
    height: usize,
    xy: &'a [i16],
    frac: &'a [u16],
}

impl<'a> RemapTable<'a> {
    /// A table over caller-provided slices (`xy`: `2·w·h`, `frac`: `w·h`;
    /// longer slices are fine).
    pub fn new(
        width: usize,
        height: usize,
        xy: &'a [i16],
        frac: &'a [u16],
    ) -> Result<Self, RemapError> {
        let (nxy, nf) = table_len(width, height).ok_or(RemapError::TableSize {
            needed_xy: usize::MAX,
            got_xy: xy.len(),
            got_frac: frac.len(),
        })?;
        if xy.len() < nxy || frac.len() < nf {
            return Err(RemapError::TableSize {
                needed_xy: nxy,
                got_xy: xy.len(),
                got_frac: frac.len(),
            });
        }
        Ok(RemapTable {
            width,
            height,
            xy,
            frac,
        })
    }

    /// Output width.
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Output height.
    pub const fn height(&self) -> usize {
        self.height
    }
}

/// Bilinear blend of a 2 × 2 neighbourhood with the table's fractions:
/// `Σ p·w` with weights `(32 − fx)(32 − fy)`, `fx(32 − fy)`, `(32 − fx)fy`,
/// `fx·fy` (sum 1024), rounded, `>> 10`.
#[inline]
fn blend(p00: u8, p01: u8, p10: u8, p11: u8, frac: u16) -> u8 {
    let t = INTER_TAB_SIZE as u32;
    let fx = (frac as u32) & (t - 1);
    let fy = ((frac as u32) >> INTER_BITS) & (t - 1);
    let top = p00 as u32 * (t - fx) + p01 as u32 * fx;
    let bottom = p10 as u32 * (t - fx) + p11 as u32 * fx;
    let v = top * (t - fy) + bottom * fy;
    ((v + (1 << (2 * INTER_BITS - 1))) >> (2 * INTER_BITS)) as u8
}

/// One output pixel from integer source `(sx, sy)` and fractions.
#[inline]
fn sample(src: &ImageView<'_>, sx: i32, sy: i32, frac: u16) -> u8 {
    let fx = (frac as u32) & (INTER_TAB_SIZE as u32 - 1);
    let fy = ((frac as u32) >> INTER_BITS) & (INTER_TAB_SIZE as u32 - 1);
    let t = INTER_TAB_SIZE as u32;
    let (w, h) = (src.width() as i64, src.height() as i64);
    let (x, y) = (sx as i64, sy as i64);
    let (p00, p01, p10, p11) = if x >= 0 && y >= 0 && x + 1 < w && y + 1 < h {
        let r0 = src.row(y as usize);
        let r1 = src.row(y as usize + 1);
        let xi = x as usize;
        (
            r0.get(xi).copied().unwrap_or(0),
            r0.get(xi + 1).copied().unwrap_or(0),
            r1.get(xi).copied().unwrap_or(0),
            r1.get(xi + 1).copied().unwrap_or(0),
        )
    } else if x >= w || x + 1 < 0 || y >= h || y + 1 < 0 {
        return 0;
    } else {
        let get = |xx: i64, yy: i64| -> u8 {
            if xx >= 0 && yy >= 0 && xx < w && yy < h {
                src.get(xx as usize, yy as usize).unwrap_or(0)
            } else {
                0
            }
        };
        (get(x, y), get(x + 1, y), get(x, y + 1), get(x + 1, y + 1))
    };
    let v = p00 as u32 * (t - fx) * (t - fy)
        + p01 as u32 * fx * (t - fy)
        + p10 as u32 * (t - fx) * fy
        + p11 as u32 * fx * fy;
    // weights sum to 1024: the result is at most 255
    ((v + (1 << (2 * INTER_BITS - 1))) >> (2 * INTER_BITS)) as u8
}

/// Bilinear remap: `dst(x, y) = src(table(x, y))`, fixed point, neighbours
/// outside `src` read as 0. `dst` must have the table's size.
pub fn remap_bilinear(
    src: &ImageView<'_>,
    table: &RemapTable<'_>,
    dst: &mut ImageViewMut<'_>,
) -> Result<(), RemapError> {
    if dst.width() != table.width || dst.height() != table.height {
        return Err(RemapError::SizeMismatch);
    }
    let w = table.width;
    for y in 0..table.height {
        let base = y * w;
        let (Some(xy), Some(fr)) = (
            table.xy.get(2 * base..2 * (base + w)),
            table.frac.get(base..base + w),
        ) else {
            return Err(RemapError::SizeMismatch);
        };
        let row = dst.row_mut(y);
        // fast path: the source rows sy, sy+1 are looked up once per change
        // of sy (rectification maps move slowly along a row), and a pixel
        // whose 2 × 2 neighbourhood is inside takes two slice reads; the
        // rest (borders, outside) goes through `sample`
        let mut cur_sy = i32::MIN;
        let (mut r0, mut r1): (&[u8], &[u8]) = (&[], &[]);
        for ((out, p), &f) in row.iter_mut().zip(xy.chunks_exact(2)).zip(fr) {
            let (sx, sy) = (p[0] as i32, p[1] as i32);
            if sy != cur_sy {
                cur_sy = sy;
                (r0, r1) = if sy >= 0 && (sy as usize) + 1 < src.height() {
                    (src.row(sy as usize), src.row(sy as usize + 1))
                } else {
                    (&[][..], &[][..])
                };
            }
            let xi = sx as usize; // negative → huge → no slice
            *out = match (
                r0.get(xi..xi.wrapping_add(2)),
                r1.get(xi..xi.wrapping_add(2)),
            ) {
                (Some(&[p00, p01]), Some(&[p10, p11])) if sx >= 0 => blend(p00, p01, p10, p11, f),
                _ => sample(src, sx, sy, f),
            };
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Float bilinear with the table's (quantized) coordinates, neighbours
    /// outside read as 0.
    fn reference(src: &ImageView<'_>, sx: i16, sy: i16, frac: u16) -> f64 {
        let fx = (frac & 31) as f64 / 32.0;
        let fy = ((frac >> 5) & 31) as f64 / 32.0;
        let g = |x: i64, y: i64| -> f64 {
            if x >= 0 && y >= 0 && (x as usize) < src.width() && (y as usize) < src.height() {
                src.get(x as usize, y as usize).unwrap() as f64
            } else {
                0.0
            }
        };
        let (x, y) = (sx as i64, sy as i64);
        g(x, y) * (1.0 - fx) * (1.0 - fy)
            + g(x + 1, y) * fx * (1.0 - fy)
            + g(x, y + 1) * (1.0 - fx) * fy
            + g(x + 1, y + 1) * fx * fy
    }

    #[test]
    fn pack_matches_opencv_convert_maps() {
        // x = 3.25 -> 104/32, y = -0.5 -> -16/32
        assert_eq!(pack(104, -16), ([3, -1], (16 * 32 + 8) as u16));
        assert_eq!(pack(i32::MIN, i32::MAX).0, [i16::MIN, i16::MAX]);
    }

    #[test]
    fn identity_table_copies_and_half_pixel_averages() {
        let src: [u8; 12] = [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110];
        let view = ImageView::packed(&src, 4, 3).unwrap();
        let mut xy = [0i16; 24];
        let mut fr = [0u16; 12];
        for y in 0..3 {
            for x in 0..4 {
                let (p, f) = pack(x * 32 + 16, y * 32);
                xy[2 * (y * 4 + x) as usize] = p[0];
                xy[2 * (y * 4 + x) as usize + 1] = p[1];
                fr[(y * 4 + x) as usize] = f;
            }
        }
        let table = RemapTable::new(4, 3, &xy, &fr).unwrap();
        let mut out = [0u8; 12];
        let mut dst = ImageViewMut::packed(&mut out, 4, 3).unwrap();
        remap_bilinear(&view, &table, &mut dst).unwrap();
        // half-way to the right neighbour; the last column blends with 0
        assert_eq!(out, [5, 15, 25, 15, 45, 55, 65, 35, 85, 95, 105, 55]);
        assert!(RemapTable::new(4, 3, &xy[..23], &fr).is_err());
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        #[test]
        fn never_panics_and_matches_float_bilinear(
            sw in 1usize..12, sh in 1usize..12, pad in 0usize..3,
            dw in 1usize..150, dh in 1usize..10,
            seed in any::<u64>(), wide in any::<bool>(),
        ) {
            let stride = sw + pad;
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let src: std::vec::Vec<u8> = (0..stride * sh).map(|_| next() as u8).collect();
            let view = ImageView::new(&src, sw, sh, stride).unwrap();
            let n = dw * dh;
            let xy: std::vec::Vec<i16> = (0..2 * n).map(|k| {
                let r = next();
                // narrow: y repeats often (the fast path's row cache)
                if wide { r as i16 } else if k % 2 == 1 { (r % 4) as i16 - 1 } else { (r % 20) as i16 - 5 }
            }).collect();
            let fr: std::vec::Vec<u16> = (0..n).map(|_| next() as u16).collect();
            let table = RemapTable::new(dw, dh, &xy, &fr).unwrap();
            let mut out = std::vec![0u8; n];
            let mut dst = ImageViewMut::packed(&mut out, dw, dh).unwrap();
            remap_bilinear(&view, &table, &mut dst).unwrap();
            for i in 0..n {
                let r = reference(&view, xy[2 * i], xy[2 * i + 1], fr[i]);
                prop_assert!((out[i] as f64 - r).abs() <= 1.0, "pixel {} got {} want {}", i, out[i], r);
                // the row-cached fast path equals the per-pixel sampler exactly
                prop_assert_eq!(out[i], sample(&view, xy[2 * i] as i32, xy[2 * i + 1] as i32, fr[i]));
            }
            // a wrong-size destination is refused, not a panic
            let mut small = std::vec![0u8; n];
            let mut bad = ImageViewMut::packed(&mut small, n, 1).unwrap();
            if n != dw || dh != 1 {
                prop_assert!(remap_bilinear(&view, &table, &mut bad).is_err());
            }
        }
    }
}
