//! Smooth background of a frame: strobe glow, vignetting and backscatter
//! (beyond the paper; used by the local segmentation,
//! `crate::segment::local`, when `Params::background` is set).
//!
//! Why: the Cam-trawl's LED strobes light the water unevenly. Inside one
//! elliptic region (Section III.A) the water can rise by more grey levels
//! across the ellipse than a dim fish stands above it, and Otsu's split
//! (eq. (1)) then separates the bright side of the glow from the dark side
//! instead of the fish from the water. Subtracting a background estimate
//! first leaves the fish on flat water.
//!
//! The estimate, on a grid of [`BLOCK`] × [`BLOCK`] pixel cells:
//! 1. `L(X, Y)`: the mean of the cell's pixels of the mesh-free frame, in
//!    sixteenths of a grey level (`round(16 · mean)`, as
//!    [`crate::lowres::box_mean16`] with factor [`BLOCK`]);
//! 2. a grey opening of `L` by the `(2r + 1) × (2r + 1)` square (erosion
//!    then dilation, cells outside the grid ignored): it removes every
//!    bright structure thinner than the square — fish, debris, mesh —
//!    and keeps the slowly varying light;
//! 3. a 3 × 3 mean of the opening (cells outside ignored, rounded half up),
//!    which smooths the opening's flat steps.
//!
//! The background at a pixel is the bilinear interpolation of the grid at
//! the pixel's position (cell centres at `BLOCK·X + (BLOCK − 1)/2`,
//! positions beyond the outer centres clamped), in fixed point with
//! weights in 32nds, rounded half up: [`BgGrid::at16`].
//!
//! Cost: the grid is 1/256 of the frame (128 × 128 for 2048²); the
//! opening's windows are evaluated directly, `4 (2r + 1)` comparisons per
//! cell, a few hundred thousand operations per frame. Per region pixel the
//! subtraction is one interpolation.

/// Side of a background cell, pixels.
pub const BLOCK: usize = 16;

/// Grey level that flat water takes after [`BgGrid::subtract_row`]: room
/// below it for pixels darker than the background estimate.
pub const OFFSET: i32 = 32;

/// Why a background could not be estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BgError {
    /// A buffer is shorter than the grid.
    BufferTooSmall,
}

/// `(⌈w / BLOCK⌉, ⌈h / BLOCK⌉)`.
pub const fn grid_size(width: usize, height: usize) -> (usize, usize) {
    crate::lowres::low_size(width, height, BLOCK)
}

/// `d[i] = max(d[i], s[i])` (or the minimum) over the common length.
fn merge(d: &mut [u16], s: &[u16], max: bool) {
    if max {
        d.iter_mut().zip(s).for_each(|(d, &v)| *d = (*d).max(v));
    } else {
        d.iter_mut().zip(s).for_each(|(d, &v)| *d = (*d).min(v));
    }
}

/// Window extremum of radius `r` along each row (cells outside ignored):
/// the row merged with itself shifted by `−r..=r`, slice by slice.
fn extremum_rows(src: &[u16], dst: &mut [u16], bw: usize, r: usize, max: bool) {
    for (srow, drow) in src.chunks_exact(bw).zip(dst.chunks_exact_mut(bw)) {
        drow.copy_from_slice(srow);
        for k in 1..=r.min(bw.saturating_sub(1)) {
            // d[x] ⊕= s[x + k] and d[x + k] ⊕= s[x]
            merge(&mut drow[..bw - k], &srow[k..], max);
            merge(&mut drow[k..], &srow[..bw - k], max);
        }
    }
}

/// Window extremum of radius `r` along each column, row slice by row
/// slice (element-wise, vectorised).
fn extremum_cols(src: &[u16], dst: &mut [u16], bw: usize, bh: usize, r: usize, max: bool) {
    for (y, drow) in dst.chunks_exact_mut(bw).enumerate().take(bh) {
        let lo = y.saturating_sub(r);
        let hi = (y + r).min(bh - 1);
        if let Some(first) = src.get(lo * bw..(lo + 1) * bw) {
            drow.copy_from_slice(first);
        }
        for yy in lo + 1..=hi {
            merge(drow, src.get(yy * bw..(yy + 1) * bw).unwrap_or(&[]), max);
        }
    }
}

/// Steps 2–3 of the module documentation: the opening of `grid`
/// (`bw × bh` cells, sixteenths of a grey level) by the `(2r + 1)²`
/// square, then its 3 × 3 mean, into `out`; `grid` is overwritten
/// (scratch), `tmp` is scratch of `bw · bh` cells. Cells must be at most
/// 7281 (`u16::MAX / 9`: the 3 × 3 sums are `u16`); cell means of 8-bit
/// frames are at most 16 · 255 = 4080.
pub fn open_smooth(
    grid: &mut [u16],
    bw: usize,
    bh: usize,
    r: usize,
    tmp: &mut [u16],
    out: &mut [u16],
) -> Result<(), BgError> {
    let n = bw * bh;
    if n == 0 {
        return Ok(());
    }
    let grid = grid.get_mut(..n).ok_or(BgError::BufferTooSmall)?;
    let tmp = tmp.get_mut(..n).ok_or(BgError::BufferTooSmall)?;
    let out = out.get_mut(..n).ok_or(BgError::BufferTooSmall)?;
    // erosion (separable square), then dilation
    extremum_rows(grid, tmp, bw, r, false);
    extremum_cols(tmp, out, bw, bh, r, false);
    extremum_rows(out, tmp, bw, r, true);
    extremum_cols(tmp, grid, bw, bh, r, true);
    // 3 × 3 mean: horizontal sums into `tmp` (≤ 3 · 4080 fits a u16),
    // then vertical sums (≤ 9 · 4080 = 36 720, a u16) into `grid`, both
    // slice-wise, then per cell the rounded division by the number of
    // cells inside
    for (srow, trow) in grid.chunks_exact(bw).zip(tmp.chunks_exact_mut(bw)) {
        trow.copy_from_slice(srow);
        if bw > 1 {
            add_u16(&mut trow[..bw - 1], &srow[1..]);
            add_u16(&mut trow[1..], &srow[..bw - 1]);
        }
    }
    for (y, (grow, orow)) in grid
        .chunks_exact_mut(bw)
        .zip(out.chunks_exact_mut(bw))
        .enumerate()
        .take(bh)
    {
        let (lo, hi) = (y.saturating_sub(1), (y + 1).min(bh - 1));
        let rows = (hi - lo + 1) as u32;
        grow.copy_from_slice(tmp.get(lo * bw..(lo + 1) * bw).unwrap_or(&[]));
        for yy in lo + 1..=hi {
            add_u16(grow, tmp.get(yy * bw..(yy + 1) * bw).unwrap_or(&[]));
        }
        // interior cells have 3 columns, the end cells 2 (1 if bw = 1)
        let inner = Div::new(rows * 3);
        let edge = Div::new(rows * bw.min(2) as u32);
        for (o, &s) in orow.iter_mut().zip(grow.iter()) {
            *o = inner.round(s as u32);
        }
        if let (Some(o), Some(&s)) = (orow.first_mut(), grow.first()) {
            *o = edge.round(s as u32);
        }
        if let (Some(o), Some(&s)) = (orow.last_mut(), grow.last()) {
            *o = edge.round(s as u32);
        }
    }
    Ok(())
}

/// `d[i] += s[i]` over the common length (sums known to fit).
fn add_u16(d: &mut [u16], s: &[u16]) {
    d.iter_mut()
        .zip(s)
        .for_each(|(d, &v)| *d = d.wrapping_add(v));
}

/// `round(s / n)` rounding half up, `⌊(2s + n) / 2n⌋`, by a multiply and a
/// shift: `⌊(2s + n) / 2n⌋ = ((2s + n) · ⌈2³⁶ / 2n⌉) >> 36`, exact for
/// `2s + n < 2¹⁸` (here `s ≤ 36 720`, `n ≤ 9`).
#[derive(Clone, Copy)]
struct Div {
    n: u64,
    m: u64,
}

impl Div {
    fn new(n: u32) -> Div {
        let n = n.max(1) as u64;
        Div {
            n,
            m: (1u64 << 36).div_ceil(2 * n),
        }
    }

    #[inline]
    fn round(&self, s: u32) -> u16 {
        (((2 * s as u64 + self.n) * self.m) >> 36).min(u16::MAX as u64) as u16
    }
}

/// Step 1 from the 4 × 4 block sums of the coarse pass
/// ([`crate::lowres::box_mean16`] with factor 4 stores `Σ` of each block
/// exactly): `L = round(Σ_{4×4 blocks} / 16)`. `low` is `lw` cells wide;
/// valid when the frame's sides are multiples of [`BLOCK`] (then
/// `lw = 4 bw`), which the caller checks, and for block sums of 8-bit
/// pixels (`≤ 16 · 255`; four rows of them are added in `u16`).
pub fn grid_from_low4(
    low: &[u16],
    lw: usize,
    bw: usize,
    bh: usize,
    grid: &mut [u16],
) -> Result<(), BgError> {
    let grid = grid.get_mut(..bw * bh).ok_or(BgError::BufferTooSmall)?;
    if low.len() < lw * bh * 4 || lw < bw * 4 {
        return Err(BgError::BufferTooSmall);
    }
    // per grid row: the four low rows summed slice-wise (≤ 4 · 4080 fits a
    // u16) in chunks of `CH` low columns, then four column sums per cell
    // (≤ 65 280, so `+ 8` still fits)
    const CH: usize = 256;
    let mut acc = [0u16; CH];
    for (gy, grow) in grid.chunks_exact_mut(bw.max(1)).enumerate() {
        let rows = low.get(4 * gy * lw..(4 * gy + 4) * lw).unwrap_or(&[]);
        let row = |k: usize| rows.get(k * lw..k * lw + 4 * bw).unwrap_or(&[]);
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        for (c, gch) in grow.chunks_mut(CH / 4).enumerate() {
            let (a, b) = (c * CH, (c * CH + 4 * gch.len()).min(4 * bw));
            let acc = &mut acc[..b - a];
            for ((((s, &p0), &p1), &p2), &p3) in acc
                .iter_mut()
                .zip(r0.get(a..b).unwrap_or(&[]))
                .zip(r1.get(a..b).unwrap_or(&[]))
                .zip(r2.get(a..b).unwrap_or(&[]))
                .zip(r3.get(a..b).unwrap_or(&[]))
            {
                *s = p0.wrapping_add(p1).wrapping_add(p2.wrapping_add(p3));
            }
            for (g, q) in gch.iter_mut().zip(acc.chunks_exact(4)) {
                let s = (q[0] as u32 + q[1] as u32) + (q[2] as u32 + q[3] as u32);
                *g = ((s + 8) / 16).min(u16::MAX as u32) as u16;
            }
        }
    }
    Ok(())
}

/// A background grid ready for interpolation.
#[derive(Debug, Clone, Copy)]
pub struct BgGrid<'a> {
    cells: &'a [u16],
    bw: usize,
    bh: usize,
}

/// Cell index and weight (32nds) of the upper neighbour along one axis
/// for pixel coordinate `p` on a grid of `n` cells.
#[inline]
fn axis(p: usize, n: usize) -> (usize, usize, u32) {
    // position in half pixels relative to cell 0's centre (BLOCK/2 − ½ px)
    let pos = 2 * p as i64 + 1 - BLOCK as i64;
    if pos <= 0 || n < 2 {
        return (0, 0, 0);
    }
    let span = 2 * BLOCK as i64; // half pixels per cell
    let c0 = (pos / span) as usize;
    if c0 + 1 >= n {
        return (n - 1, n - 1, 0);
    }
    // weight in 32nds: (pos mod span) · 32 / span, exact for BLOCK = 16
    let w = ((pos % span) * 32 / span) as u32;
    (c0, c0 + 1, w)
}

impl<'a> BgGrid<'a> {
    /// A grid of `bw × bh` cells; `None` if `cells` is shorter.
    pub fn new(cells: &'a [u16], bw: usize, bh: usize) -> Option<BgGrid<'a>> {
        let cells = cells.get(..bw.checked_mul(bh)?)?;
        if bw == 0 || bh == 0 {
            return None;
        }
        Some(BgGrid { cells, bw, bh })
    }

    fn cell(&self, x: usize, y: usize) -> u32 {
        self.cells.get(y * self.bw + x).copied().unwrap_or(0) as u32
    }

    /// The background at pixel `(x, y)`, sixteenths of a grey level.
    pub fn at16(&self, x: usize, y: usize) -> u16 {
        let (x0, x1, wx) = axis(x, self.bw);
        let (y0, y1, wy) = axis(y, self.bh);
        let top = self.cell(x0, y0) * (32 - wx) + self.cell(x1, y0) * wx;
        let bot = self.cell(x0, y1) * (32 - wx) + self.cell(x1, y1) * wx;
        ((top * (32 - wy) + bot * wy + 512) >> 10) as u16
    }

    /// Replaces the pixels `px` of frame row `y` starting at column `x0`
    /// by `clamp(p − round(B) + OFFSET, 0, 255)`, `B` the background
    /// ([`BgGrid::at16`] rounded to a grey level).
    ///
    /// Cost: the row is walked cell interval by cell interval; inside one
    /// the weight steps by 2/32 per pixel, so a pixel costs two multiplies,
    /// two shifts and the clamp (no division, no lookup).
    pub fn subtract_row(&self, y: usize, x0: usize, px: &mut [u8]) {
        let (y0, y1, wy) = axis(y, self.bh);
        // the grid column `c` interpolated to row y, times 32
        let col = |c: usize| self.cell(c, y0) * (32 - wy) + self.cell(c, y1) * wy;
        let put = |p: &mut u8, v: u32| {
            let bg = (((v + 512) >> 10) + 8) >> 4;
            *p = (*p as i32 - bg as i32 + OFFSET).clamp(0, 255) as u8;
        };
        let n = self.bw;
        let len = px.len();
        // position in half pixels from cell 0's centre (see `axis`)
        let mut pos = 2 * x0 as i64 + 1 - BLOCK as i64;
        let mut i = 0usize;
        if n < 2 || pos <= 0 {
            // left of the first centre (or a one-cell grid): cell 0
            let k = if n < 2 {
                len
            } else {
                ((-pos / 2 + 1) as usize).min(len)
            };
            let v = col(0) * 32;
            px.iter_mut().take(k).for_each(|p| put(p, v));
            i = k;
            pos += 2 * k as i64;
        }
        let span = 2 * BLOCK as i64;
        while i < len {
            let c = (pos / span) as usize;
            if c + 1 >= n {
                let v = col(n - 1) * 32;
                px.iter_mut().skip(i).for_each(|p| put(p, v));
                break;
            }
            let (a, b) = (col(c), col(c + 1));
            let w = (pos % span) as u32; // 32nds; steps by 2 per pixel
            let k = ((33 - w) / 2).max(1) as usize; // w, w + 2, …, ≤ 31
            let end = (i + k).min(len);
            // a·(32 − w) + b·w, stepped by 2 (b − a) per pixel (< 2³¹: a
            // and b are at most 32 · 65 535); pixel j of the interval as
            // v + j · step, a closed form the compiler vectorises
            let v = (a * (32 - w) + b * w) as i32;
            let step = 2 * (b as i32 - a as i32);
            // the interval's (≤ 16) background levels minus OFFSET, all 16
            // computed (a fixed trip count: vectorised), then subtracted
            let mut bg = [0i16; 16];
            for (j, g) in bg.iter_mut().enumerate() {
                let t = v + j as i32 * step + 512;
                *g = ((((t >> 10) + 8) >> 4) - OFFSET) as i16;
            }
            let part = px.get_mut(i..end).unwrap_or(&mut []);
            for (p, &g) in part.iter_mut().zip(bg.iter()) {
                *p = (*p as i16 - g).clamp(0, 255) as u8;
            }
            pos += 2 * (end - i) as i64;
            i = end;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    extern crate std;
    use std::vec;
    use std::vec::Vec;

    /// The opening and 3 × 3 mean written as 2-D windows.
    fn naive_open_smooth(g: &[u16], bw: usize, bh: usize, r: usize) -> Vec<u16> {
        let win = |src: &[u16], x: usize, y: usize, rad: usize, max: bool| {
            let mut v: Option<u16> = None;
            for yy in y.saturating_sub(rad)..=(y + rad).min(bh - 1) {
                for xx in x.saturating_sub(rad)..=(x + rad).min(bw - 1) {
                    let p = src[yy * bw + xx];
                    v = Some(match v {
                        None => p,
                        Some(q) if max => q.max(p),
                        Some(q) => q.min(p),
                    });
                }
            }
            v.unwrap()
        };
        let e: Vec<u16> = (0..bw * bh)
            .map(|i| win(g, i % bw, i / bw, r, false))
            .collect();
        let o: Vec<u16> = (0..bw * bh)
            .map(|i| win(&e, i % bw, i / bw, r, true))
            .collect();
        (0..bw * bh)
            .map(|i| {
                let (x, y) = (i % bw, i / bw);
                let (mut s, mut c) = (0f64, 0f64);
                for yy in y.saturating_sub(1)..=(y + 1).min(bh - 1) {
                    for xx in x.saturating_sub(1)..=(x + 1).min(bw - 1) {
                        s += o[yy * bw + xx] as f64;
                        c += 1.0;
                    }
                }
                (s / c + 0.5).floor() as u16
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 200 }))]
        #[test]
        fn open_smooth_equals_the_2d_windows(
            bw in 1usize..20, bh in 1usize..20, r in 0usize..6, seed in any::<u64>(),
        ) {
            let mut s = seed | 1;
            let g: Vec<u16> = (0..bw * bh).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 52) as u16
            }).collect();
            let want = naive_open_smooth(&g, bw, bh, r);
            let (mut gg, mut tmp, mut out) = (g.clone(), vec![0u16; bw * bh], vec![0u16; bw * bh]);
            open_smooth(&mut gg, bw, bh, r, &mut tmp, &mut out).unwrap();
            prop_assert_eq!(out, want);
        }

        /// The chunked block sums equal the direct 16 × 16 block mean
        /// (grids wider than one chunk of 64 cells included).
        #[test]
        fn grid_from_low4_equals_box_mean16(bw in 1usize..80, bh in 1usize..4, seed in any::<u64>()) {
            let (w, h) = (16 * bw, 16 * bh);
            let mut s = seed | 1;
            let px: Vec<u8> = (0..w * h).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 24) as u8
            }).collect();
            let img = crate::image::ImageView::packed(&px, w, h).unwrap();
            let mut low = vec![0u16; w * h / 16];
            crate::lowres::box_mean16(img, 4, &mut low).unwrap();
            let mut direct = vec![0u16; bw * bh];
            crate::lowres::box_mean16(img, 16, &mut direct).unwrap();
            let mut grid = vec![0u16; bw * bh];
            grid_from_low4(&low, w / 4, bw, bh, &mut grid).unwrap();
            prop_assert_eq!(grid, direct);
        }

        #[test]
        fn subtract_row_is_the_interpolated_background(
            bw in 1usize..8, bh in 1usize..8, seed in any::<u64>(),
            y in 0usize..140, x0 in 0usize..140, len in 0usize..60, p in any::<u8>(),
        ) {
            let mut s = seed | 1;
            let cells: Vec<u16> = (0..bw * bh).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 52) as u16
            }).collect();
            let g = BgGrid::new(&cells, bw, bh).unwrap();
            let mut row = vec![p; len];
            g.subtract_row(y, x0, &mut row);
            for (i, &v) in row.iter().enumerate() {
                let bg = (g.at16(x0 + i, y) as i32 + 8) >> 4;
                prop_assert_eq!(v as i32, (p as i32 - bg + OFFSET).clamp(0, 255));
                // the interpolation stays within the cells' range
                let (lo, hi) = (cells.iter().min().unwrap(), cells.iter().max().unwrap());
                prop_assert!(g.at16(x0 + i, y) >= *lo && g.at16(x0 + i, y) <= *hi);
            }
        }
    }

    #[test]
    fn flat_background_is_flat_and_thin_bright_things_are_opened_away() {
        let (bw, bh) = (12, 10);
        let mut g = [16 * 40u16; 120];
        g[5 * bw + 6] = 16 * 200; // one bright cell: thinner than the 3 × 3 square
        let (mut tmp, mut out) = ([0u16; 120], [0u16; 120]);
        open_smooth(&mut g, bw, bh, 1, &mut tmp, &mut out).unwrap();
        assert!(out.iter().all(|&v| v == 16 * 40));
        let grid = BgGrid::new(&out, bw, bh).unwrap();
        let mut row = [60u8; 100];
        grid.subtract_row(37, 3, &mut row);
        assert!(row.iter().all(|&v| v as i32 == 60 - 40 + OFFSET));
    }

    #[test]
    fn interpolation_hits_cell_centres_and_is_linear_between() {
        let (bw, bh) = (3, 2);
        let cells = [0u16, 320, 640, 0, 320, 640];
        let g = BgGrid::new(&cells, bw, bh).unwrap();
        // cell centres at 7.5, 23.5, 39.5: pixel 7 and 8 straddle centre 0
        assert_eq!(g.at16(0, 0), 0);
        assert_eq!(g.at16(7, 0), 0);
        assert_eq!(g.at16(8, 0), 10); // 1/32 of 320
        assert_eq!(g.at16(15, 0), 150); // 15/32 of 320
        assert_eq!(g.at16(24, 0), 330);
        assert_eq!(g.at16(47, 20), 640);
    }

    #[test]
    fn grid_from_low4_equals_the_direct_block_mean() {
        // a 32 × 32 frame of varied pixels: 4 × 4 sums, then the 16 × 16 mean
        let (w, h) = (32usize, 32usize);
        let px: [u8; 1024] = core::array::from_fn(|i| ((i * 37 + (i / 32) * 11) % 251) as u8);
        let img = crate::image::ImageView::packed(&px, w, h).unwrap();
        let mut low = [0u16; 64];
        crate::lowres::box_mean16(img, 4, &mut low).unwrap();
        let mut direct = [0u16; 4];
        crate::lowres::box_mean16(img, 16, &mut direct).unwrap();
        let mut grid = [0u16; 4];
        grid_from_low4(&low, 8, 2, 2, &mut grid).unwrap();
        assert_eq!(grid, direct);
    }
}
