//! Disparity refinement (Section IV.D.2; Section V.D: 8 × 8 blocks, r = 16).
//!
//! A dense grid of `B_s × B_s` blocks (`Params::refine_block`) tiles the
//! object's upright box; a block is used when at least half of its pixels
//! belong to the object mask. Each block searches the disparities
//! `[d_o − r, d_o + r]` (`r = Params::refine_range`) by SAD per pixel and
//! keeps the minimum, refined to sub-pixel by an equiangular (V-shaped) fit through the SADs at
//! `d − 1, d, d + 1`. Blocks whose minimum lies on the edge of the search
//! interval are rejected (the true disparity is likely outside).
//! Aggregation (a robust line of disparity along the fish axis) is done by
//! the caller, [`crate::length`].
//!
//! The grid is spaced out (blocks stay `B_s × B_s`) so that it never holds
//! more than `B` blocks ([`grid_step_for`]).
//!
//! Memory bound: `B` blocks of 16 bytes (const generic) and one row of
//! `MAX_GRID_COLS` coverage counters on the stack. Work: blocks ·
//! `(2r + 1)` · `B_s²` absolute differences, counted in [`Refined::sad_ops`].

use crate::error::ImageError;
use crate::image::{ImageView, Roi};
use crate::object::Run;
use crate::stereo::sad_per_pixel;

/// Most grid columns handled across one object; wider objects use a
/// proportionally larger grid step.
pub const MAX_GRID_COLS: usize = 256;

/// One refined block: centre (left view, pixels), disparity, SAD per pixel.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RefinedBlock {
    /// Block centre x.
    pub x: f32,
    /// Block centre y.
    pub y: f32,
    /// Sub-pixel disparity.
    pub d: f32,
    /// Minimum SAD per pixel.
    pub sad: f32,
}

/// The refined blocks of one object.
#[derive(Debug, Clone, Default)]
pub struct Refined<const B: usize> {
    /// Accepted blocks.
    pub blocks: heapless::Vec<RefinedBlock, B>,
    /// Blocks that did not fit in `B`.
    pub dropped: u32,
    /// Blocks rejected (minimum on the search edge, or no comparable pixels).
    pub rejected: u32,
    /// Absolute differences computed.
    pub sad_ops: u64,
}

/// Smallest grid step `s` with `⌊w/s⌋·⌊h/s⌋ ≤ cap` blocks, from
/// `s = ⌈√(w·h/cap)⌉` upwards (at most a few steps).
pub fn grid_step_for(w: u32, h: u32, cap: usize) -> u32 {
    let cap = cap.max(1) as u64;
    let area = w as u64 * h as u64;
    let mut s = 1u64;
    while s * s * cap < area {
        s += 1;
        if s > 1 << 16 {
            break;
        }
    }
    while s < 1 << 16 && (w as u64 / s) * (h as u64 / s) > cap {
        s += 1;
    }
    s as u32
}

/// The left block of side `S` at `(x0, y0)`, gathered once per block for
/// [`block_sad`]; `None` unless the block and its copies shifted by every
/// disparity in `[d_lo, d_hi]` lie wholly inside both views (then
/// [`sad_per_pixel`] compares all `S²` pixels for each of them).
fn gather_block<const S: usize>(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    x0: u32,
    y0: u32,
    d_lo: i32,
    d_hi: i32,
) -> Option<[[u8; S]; S]> {
    let (x0l, y0l, sl) = (x0 as i64, y0 as i64, S as i64);
    let (w, h) = (left.width() as i64, left.height() as i64);
    let inside = y0l + sl <= h
        && y0l + sl <= right.height() as i64
        && x0l + sl <= w
        && x0l >= d_hi as i64
        && x0l + sl <= right.width() as i64 + d_lo as i64;
    if !inside {
        return None;
    }
    let mut b = [[0u8; S]; S];
    for (j, row) in b.iter_mut().enumerate() {
        let src = left
            .row(y0 as usize + j)
            .get(x0 as usize..x0 as usize + S)?;
        row.copy_from_slice(src);
    }
    Some(b)
}

/// [`sad_per_pixel`] of a gathered block (see [`gather_block`]) at
/// disparity `d`: the same sum over the same `S²` pixels, so the same value.
fn block_sad<const S: usize>(
    lb: &[[u8; S]; S],
    right: &ImageView<'_>,
    x0: u32,
    y0: u32,
    d: i32,
    ops: &mut u64,
) -> Option<f32> {
    let xs = (x0 as i64 - d as i64) as usize;
    let mut sum = 0u32;
    for (j, lrow) in lb.iter().enumerate() {
        let rrow: &[u8; S] = right
            .row(y0 as usize + j)
            .get(xs..xs + S)?
            .try_into()
            .ok()?;
        for i in 0..S {
            sum += lrow[i].abs_diff(rrow[i]) as u32;
        }
    }
    let n = (S * S) as u64;
    *ops += n;
    Some(sum as f32 / n as f32)
}

/// Widest right-view window [`gather_window`] holds: the block side plus
/// the disparity span (`8 + 33` for the default block and range).
const WINDOW: usize = 64;

/// The right-view rows of a gathered block's search (see [`gather_block`],
/// whose inside test this relies on): columns `x0 − d_hi ..
/// x0 − d_lo + S` of rows `y0 .. y0 + S`, so each disparity's block is a
/// slice at offset `d_hi − d` of it, without a per-row image lookup;
/// `None` when that is wider than [`WINDOW`].
fn gather_window<const S: usize>(
    right: &ImageView<'_>,
    x0: u32,
    y0: u32,
    d_lo: i32,
    d_hi: i32,
) -> Option<[[u8; WINDOW]; S]> {
    let span = usize::try_from(d_hi as i64 - d_lo as i64).ok()? + S;
    let xs = usize::try_from(x0 as i64 - d_hi as i64).ok()?;
    if span > WINDOW {
        return None;
    }
    let mut b = [[0u8; WINDOW]; S];
    for (j, row) in b.iter_mut().enumerate() {
        let src = right.row(y0 as usize + j).get(xs..xs + span)?;
        row.get_mut(..span)?.copy_from_slice(src);
    }
    Some(b)
}

/// [`block_sad`] on a gathered window ([`gather_window`]): the block at
/// offset `off` of each window row (the same sum, so the same value).
fn window_sad<const S: usize>(
    lb: &[[u8; S]; S],
    win: &[[u8; WINDOW]; S],
    off: usize,
    ops: &mut u64,
) -> Option<f32> {
    let mut sum = 0u32;
    for (lrow, wrow) in lb.iter().zip(win) {
        let rrow: &[u8; S] = wrow.get(off..off + S)?.try_into().ok()?;
        for i in 0..S {
            sum += lrow[i].abs_diff(rrow[i]) as u32;
        }
    }
    let n = (S * S) as u64;
    *ops += n;
    Some(sum as f32 / n as f32)
}

/// SADs per pixel of one `bs × bs` block at `(bx0, y0)` for every
/// disparity of `[d_lo, d_hi]`, in order, through `f(d, sad)`: the gathered
/// fixed-size path for the common block sides when the search stays inside
/// both views, [`sad_per_pixel`] otherwise (identical values).
#[allow(clippy::too_many_arguments)]
fn block_sads(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    bx0: u32,
    y0: u32,
    bs: u32,
    d_lo: i32,
    d_hi: i32,
    ops: &mut u64,
    mut f: impl FnMut(i32, Option<f32>),
) {
    macro_rules! fixed {
        ($s:literal) => {
            if bs == $s {
                if let Some(lb) = gather_block::<$s>(left, right, bx0, y0, d_lo, d_hi) {
                    if let Some(win) = gather_window::<$s>(right, bx0, y0, d_lo, d_hi) {
                        for d in d_lo..=d_hi {
                            let off = (d_hi - d) as usize;
                            f(d, window_sad::<$s>(&lb, &win, off, ops));
                        }
                        return;
                    }
                    for d in d_lo..=d_hi {
                        f(d, block_sad::<$s>(&lb, right, bx0, y0, d, ops));
                    }
                    return;
                }
            }
        };
    }
    fixed!(8);
    fixed!(16);
    for d in d_lo..=d_hi {
        f(
            d,
            sad_per_pixel(left, right, bx0, bx0 + bs, y0, y0 + bs, d, ops),
        );
    }
}

/// Refines the disparity of one object (mask `runs`, upright box `bbox`)
/// around the coarse disparity `d_o`.
pub fn refine_disparity<const B: usize>(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    runs: &[Run],
    bbox: Roi,
    d_o: f32,
    block: u32,
    range: u32,
) -> Result<Refined<B>, ImageError> {
    if left.width() != right.width() || left.height() != right.height() {
        return Err(ImageError::SizeMismatch);
    }
    let mut out = Refined::<B>::default();
    let bbox = bbox.intersect(&left.bounds());
    if bbox.is_empty() || block == 0 || !d_o.is_finite() {
        return Ok(out);
    }
    let range = range.min(1024) as i32;
    let d0 = micromath::F32(d_o).round().0;
    let d0 = d0.clamp(-65_536.0, 65_536.0) as i32;
    // grid step: the block size, or wider for very wide objects, and wide
    // enough that the whole grid fits `B` (a truncated grid would keep only
    // the top rows of a large object and bias the disparity line)
    let step = block
        .max(bbox.w.div_ceil(MAX_GRID_COLS as u32))
        .max(grid_step_for(bbox.w, bbox.h, B));
    let cols = (bbox.w / step) as usize;
    let rows = bbox.h / step;
    let x_off = bbox.x + (bbox.w - cols as u32 * step) / 2;
    let y_off = bbox.y + (bbox.h - rows * step) / 2;
    let mut cover = [0u32; MAX_GRID_COLS];
    for gy in 0..rows {
        let y0 = y_off + gy * step;
        let y1 = y0 + block.min(step);
        cover.iter_mut().for_each(|c| *c = 0);
        for r in runs.iter() {
            let y = r.y as u32;
            if y < y0 || y >= y1 {
                continue;
            }
            for (gx, c) in cover.iter_mut().enumerate().take(cols) {
                let bx0 = x_off + gx as u32 * step;
                let bx1 = bx0 + block.min(step);
                let a = (r.x0 as u32).max(bx0);
                let b = (r.x1 as u32).min(bx1);
                if b > a {
                    *c += b - a;
                }
            }
        }
        let bs = block.min(step);
        for (gx, c) in cover.iter().enumerate().take(cols) {
            if 2 * *c < bs * bs {
                continue;
            }
            let bx0 = x_off + gx as u32 * step;
            let mut best = (f32::INFINITY, 0i32);
            let mut sads = [f32::INFINITY; 3];
            let mut prev = f32::INFINITY;
            let mut after_best = false;
            let mut ops = 0u64;
            block_sads(
                left,
                right,
                bx0,
                y0,
                bs,
                d0 - range,
                d0 + range,
                &mut ops,
                |d, s| {
                    let s = s.unwrap_or(f32::INFINITY);
                    if after_best {
                        sads[2] = s;
                        after_best = false;
                    }
                    if s < best.0 {
                        best = (s, d);
                        sads = [prev, s, f32::INFINITY];
                        after_best = true;
                    }
                    prev = s;
                },
            );
            out.sad_ops += ops;
            if !best.0.is_finite() || best.1 == d0 - range || best.1 == d0 + range {
                out.rejected += 1;
                continue;
            }
            // sub-pixel: equiangular (V) fit through (d−1, d, d+1), the
            // natural model of SAD near its minimum
            let (a, b, c2) = (sads[0], sads[1], sads[2]);
            let mut frac = 0.0;
            if a.is_finite() && c2.is_finite() {
                let den = if a < c2 { c2 - b } else { a - b };
                if den > 1e-6 {
                    frac = (0.5 * (a - c2) / den).clamp(-0.5, 0.5);
                }
            }
            let rb = RefinedBlock {
                x: bx0 as f32 + bs as f32 * 0.5 - 0.5,
                y: y0 as f32 + bs as f32 * 0.5 - 0.5,
                d: best.1 as f32 + frac,
                sad: best.0,
            };
            if out.blocks.push(rb).is_err() {
                out.dropped += 1;
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// A `w × h` textured left frame and its right view shifted by a
    /// constant disparity `d`.
    fn shifted_pair(w: usize, h: usize, d: i32) -> (Vec<u8>, Vec<u8>) {
        let mut l = vec![0u8; w * h];
        let mut r = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                l[y * w + x] = tex(x as i32, y as i32);
                r[y * w + x] = tex(x as i32 + d, y as i32);
            }
        }
        (l, r)
    }

    fn tex(x: i32, y: i32) -> u8 {
        let h = (x.wrapping_mul(73856093) ^ y.wrapping_mul(19349663)) as u32;
        (40 + (h >> 7) % 150) as u8
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 256 }))]
        /// The gathered fixed-size path gives exactly `sad_per_pixel`'s
        /// values and operation count, inside and across the borders.
        #[test]
        fn block_sads_equal_sad_per_pixel(
            w in 8usize..90, h in 8usize..40, seed in proptest::prelude::any::<u32>(),
            bx0 in 0u32..90, y0 in 0u32..40, bs in proptest::sample::select(vec![2u32, 7, 8, 16]),
            d_lo in -40i32..40, span in 0i32..60,
        ) {
            let img = |k: u32| -> Vec<u8> {
                (0..w * h).map(|i| tex(i as i32, (seed ^ k) as i32)).collect()
            };
            let (l, r) = (img(0), img(0x9e37_79b9));
            let lv = ImageView::packed(&l, w, h).unwrap();
            let rv = ImageView::packed(&r, w, h).unwrap();
            let (mut ops_a, mut ops_b) = (0u64, 0u64);
            let mut got = Vec::new();
            block_sads(&lv, &rv, bx0, y0, bs, d_lo, d_lo + span, &mut ops_a, |d, s| got.push((d, s)));
            let want: Vec<(i32, Option<f32>)> = (d_lo..=d_lo + span)
                .map(|d| (d, sad_per_pixel(&lv, &rv, bx0, bx0 + bs, y0, y0 + bs, d, &mut ops_b)))
                .collect();
            proptest::prop_assert_eq!(got, want);
            proptest::prop_assert_eq!(ops_a, ops_b);
        }
    }

    #[test]
    fn grid_step_keeps_the_grid_within_capacity() {
        for (w, h, cap) in [
            (800u32, 300u32, 1024usize),
            (2048, 2048, 1024),
            (8, 8, 1),
            (5, 3, 64),
            (1000, 10, 16),
        ] {
            let s = grid_step_for(w, h, cap);
            assert!(
                (w / s) as usize * (h / s) as usize <= cap,
                "{w}x{h} cap {cap}: step {s}"
            );
            // the smallest such step, or the area bound
            if s > 1 {
                let t = s - 1;
                assert!(
                    (w / t) as usize * (h / t) as usize > cap
                        || (t as u64).pow(2) * (cap as u64) < (w as u64 * h as u64),
                    "{w}x{h} cap {cap}: step {s} not minimal"
                );
            }
        }
    }

    #[test]
    fn a_large_object_is_sampled_over_its_whole_height() {
        let (w, h) = (400usize, 200usize);
        let (l, r) = shifted_pair(w, h, 11);
        let lv = ImageView::packed(&l, w, h).unwrap();
        let rv = ImageView::packed(&r, w, h).unwrap();
        let runs: Vec<Run> = (0..200).map(|y| Run { y, x0: 40, x1: 400 }).collect();
        // 45 × 25 grid cells of 8 px would be 1125 blocks: 64 fit
        let out = refine_disparity::<64>(&lv, &rv, &runs, Roi::new(40, 0, 360, 200), 12.0, 8, 16)
            .unwrap();
        assert_eq!(out.dropped, 0);
        assert!(out.blocks.len() >= 32, "{}", out.blocks.len());
        let ys: Vec<f32> = out.blocks.iter().map(|b| b.y).collect();
        let (lo, hi) = ys
            .iter()
            .fold((f32::MAX, f32::MIN), |a, &y| (a.0.min(y), a.1.max(y)));
        assert!(lo < 40.0 && hi > 140.0, "rows {lo}..{hi}");
    }

    #[test]
    fn recovers_a_constant_shift() {
        let (w, h) = (160usize, 80usize);
        let d = 23i32;
        let (l, r) = shifted_pair(w, h, d);
        let lv = ImageView::packed(&l, w, h).unwrap();
        let rv = ImageView::packed(&r, w, h).unwrap();
        let runs: Vec<Run> = (20..60).map(|y| Run { y, x0: 50, x1: 130 }).collect();
        let out = refine_disparity::<256>(&lv, &rv, &runs, Roi::new(50, 20, 80, 40), 30.0, 8, 16)
            .unwrap();
        assert!(out.blocks.len() >= 40);
        let mut mean = 0.0;
        for b in out.blocks.iter() {
            assert!((b.d - d as f32).abs() < 0.2, "{b:?}");
            mean += b.d / out.blocks.len() as f32;
        }
        assert!((mean - d as f32).abs() < 0.05, "{mean}");
        // true disparity outside the search range: only poor matches remain
        let out = refine_disparity::<256>(&lv, &rv, &runs, Roi::new(50, 20, 80, 40), 60.0, 8, 16)
            .unwrap();
        assert!(out.blocks.iter().all(|b| b.sad > 20.0));
    }
}
