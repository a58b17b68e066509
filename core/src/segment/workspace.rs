//! Layout of the caller-provided segmentation workspace: typed views of a
//! `&mut [u8]` carved with `bytemuck` (no `unsafe`), each part aligned.

use crate::label::{StreamLabeler, RUN_WORDS, SLOT_WORDS};
use crate::morph::{disk_scratch_len, MAX_SE};

/// Most coarse regions kept per frame (the largest win on overflow).
pub const MAX_REGIONS: usize = 512;

/// Most components per region that pass the area test of eq. (4) and get
/// statistics; further ones are counted in `SegmentStats::label_overflow`.
pub const MAX_ROI_COMPONENTS: usize = 256;

/// Words of a region record: cx, cy, a, b, angle, coarse area.
pub(crate) const REGION_WORDS: usize = 8;

/// Words of a per-component statistics record: moments (10), Σp, Σp²,
/// 16-bin histogram (16), the edge test's samples (4:
/// [`super::local::EdgeSteps`]), the grey levels the mesh removal took
/// (1: [`super::local::removed_sum`]).
pub(crate) const STAT_WORDS: usize = 33;

/// Bytes of ROI scratch per ROI pixel: four 8-bit masks and an `i32` label.
pub const BYTES_PER_ROI_PIXEL: usize = 8;

const SLACK: usize = 8; // alignment padding per part

/// Smallest reduced-resolution factor of the coarse pass other than 1
/// (`Params::coarse_scale`): it sizes the reduced-resolution buffers.
pub const MIN_COARSE_SCALE: usize = 4;

/// Bins of the coarse gradient's median/MAD histograms (values clamped).
pub(crate) const LOW_HIST_BINS: usize = 1024;

/// Bytes of the reduced-resolution buffers of the coarse pass for a
/// `width × height` frame: per low-resolution pixel the downsampled frame
/// and its gradient (`u16` each), a label (`i32`), a mask and a seed flag
/// (`u8` each), plus two histograms and 8 bytes per low-resolution row
/// (the run table's row starts and extra words). They live in the
/// gradient buffer, which the reduced-resolution pass does not otherwise
/// need.
pub const fn lowres_size(width: usize, height: usize) -> usize {
    let (lw, lh) = crate::lowres::low_size(width, height, MIN_COARSE_SCALE);
    lw * lh * 10 + 2 * LOW_HIST_BINS * 4 + lh * 8 + 4 + 7 * SLACK
}

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Bytes of the frame-sized part of the workspace (everything but the ROI
/// buffers) for a `width × height` frame.
pub const fn fixed_size(width: usize, height: usize) -> usize {
    let n = width * height;
    let t = StreamLabeler::table_len(width);
    let r = StreamLabeler::runs_len(width);
    n + max(n, lowres_size(width, height))  // mesh-free frame, gradient / tmp
        + disk_scratch_len(width, MAX_SE / 2)
        + t * SLOT_WORDS * 8 + t * 4        // label slots, free list
        + 2 * r * RUN_WORDS * 4             // run rows
        + MAX_REGIONS * REGION_WORDS * 4
        + height * 8                        // ellipse spans
        + (height + 1) * 4 + height * 4     // run table: row starts, extra words
        + MAX_ROI_COMPONENTS * STAT_WORDS * 8
        + 14 * SLACK
}

/// Workspace bytes [`super::segment_frame`] needs for `width × height`
/// frames and regions of interest of up to `max_roi_pixels` pixels.
pub const fn workspace_size(width: usize, height: usize, max_roi_pixels: usize) -> usize {
    fixed_size(width, height) + max_roi_pixels * BYTES_PER_ROI_PIXEL + 2 * SLACK
}

/// The carved workspace.
pub(crate) struct Ws<'a> {
    pub filtered: &'a mut [u8],
    pub grad: &'a mut [u8],
    pub disk: &'a mut [u8],
    pub slots: &'a mut [[u64; SLOT_WORDS]],
    pub free: &'a mut [u32],
    pub prev: &'a mut [[u32; RUN_WORDS]],
    pub cur: &'a mut [[u32; RUN_WORDS]],
    pub regions: &'a mut [[f32; REGION_WORDS]],
    pub spans: &'a mut [[i32; 2]],
    pub stats: &'a mut [[u64; STAT_WORDS]],
    pub roi: RoiBufs<'a>,
}

/// ROI-sized buffers (`max_pixels` each).
pub(crate) struct RoiBufs<'a> {
    pub a: &'a mut [u8],
    pub b: &'a mut [u8],
    pub c: &'a mut [u8],
    pub d: &'a mut [u8],
    /// `max_pixels + height` words: an ROI's run table (both labellings;
    /// up to `(n + rows) / 2` runs of 2 words, [`crate::label::run_capacity`])
    /// or, with `split_merged`, its final label image.
    pub labels: &'a mut [i32],
    /// Start of each ROI row's runs in the run table (`height + 1`).
    pub row_runs: &'a mut [u32],
    pub max_pixels: usize,
}

fn carve<T: bytemuck::Pod>(ws: &mut [u8], n: usize) -> Option<(&mut [T], &mut [u8])> {
    let size = core::mem::size_of::<T>();
    let off = ws.as_ptr().align_offset(core::mem::align_of::<T>());
    let bytes = n.checked_mul(size)?;
    if off > ws.len() || ws.len() - off < bytes {
        return None;
    }
    let (_, rest) = ws.split_at_mut(off);
    let (mine, rest) = rest.split_at_mut(bytes);
    let typed = bytemuck::try_cast_slice_mut(mine).ok()?;
    Some((typed, rest))
}

/// The reduced-resolution buffers of the coarse pass (`n` pixels each).
pub(crate) struct LowBufs<'a> {
    pub img: &'a mut [u16],
    pub grad: &'a mut [u16],
    /// `n + rows` words: the hysteresis mask's run table
    /// ([`crate::label::label_runs_in`]).
    pub labels: &'a mut [i32],
    pub mask: &'a mut [u8],
    pub seeded: &'a mut [u8],
    /// Start of each row's runs in the run table (`rows + 1`).
    pub row_runs: &'a mut [u32],
    pub hist: &'a mut [u32],
    pub dev: &'a mut [u32],
}

impl<'a> LowBufs<'a> {
    /// Carves `buf` for `n` low-resolution pixels in `rows` rows.
    pub fn carve(buf: &'a mut [u8], n: usize, rows: usize) -> Option<LowBufs<'a>> {
        let (img, buf) = carve::<u16>(buf, n)?;
        let (grad, buf) = carve::<u16>(buf, n)?;
        let (labels, buf) = carve::<i32>(buf, n + rows)?;
        let (hist, buf) = carve::<u32>(buf, LOW_HIST_BINS)?;
        let (dev, buf) = carve::<u32>(buf, LOW_HIST_BINS)?;
        let (mask, buf) = carve::<u8>(buf, n)?;
        let (seeded, buf) = carve::<u8>(buf, n)?;
        let (row_runs, _) = carve::<u32>(buf, rows + 1)?;
        Some(LowBufs {
            img,
            grad,
            labels,
            mask,
            seeded,
            row_runs,
            hist,
            dev,
        })
    }
}

impl<'a> Ws<'a> {
    /// Carves `ws` for a `width × height` frame; the ROI capacity is what
    /// is left. `None` when even the frame part does not fit.
    pub fn carve(ws: &'a mut [u8], width: usize, height: usize) -> Option<Ws<'a>> {
        let n = width.checked_mul(height)?;
        let t = StreamLabeler::table_len(width);
        let r = StreamLabeler::runs_len(width);
        // the mesh-free frame word-aligned (`lowres::box_mean16` reads its
        // rows as 32-bit words; the few bytes fit the part's SLACK)
        let (filtered, ws) = carve::<u32>(ws, n.div_ceil(4))?;
        let filtered = bytemuck::cast_slice_mut::<u32, u8>(filtered)
            .get_mut(..n)
            .unwrap_or(&mut []);
        let (grad, ws) = carve::<u8>(ws, max(n, lowres_size(width, height)))?;
        let (disk, ws) = carve::<u8>(ws, disk_scratch_len(width, MAX_SE / 2))?;
        let (slots, ws) = carve::<[u64; SLOT_WORDS]>(ws, t)?;
        let (free, ws) = carve::<u32>(ws, t)?;
        let (prev, ws) = carve::<[u32; RUN_WORDS]>(ws, r)?;
        let (cur, ws) = carve::<[u32; RUN_WORDS]>(ws, r)?;
        let (regions, ws) = carve::<[f32; REGION_WORDS]>(ws, MAX_REGIONS)?;
        let (spans, ws) = carve::<[i32; 2]>(ws, height)?;
        let (stats, ws) = carve::<[u64; STAT_WORDS]>(ws, MAX_ROI_COMPONENTS)?;
        let (row_runs, ws) = carve::<u32>(ws, height + 1)?;
        let m = ws.len().saturating_sub(2 * SLACK + height * 4 + SLACK) / BYTES_PER_ROI_PIXEL;
        let (labels, ws) = carve::<i32>(ws, m + height)?;
        let (a, ws) = carve::<u8>(ws, m)?;
        let (b, ws) = carve::<u8>(ws, m)?;
        let (c, ws) = carve::<u8>(ws, m)?;
        let (d, _) = carve::<u8>(ws, m)?;
        Some(Ws {
            filtered,
            grad,
            disk,
            slots,
            free,
            prev,
            cur,
            regions,
            spans,
            stats,
            roi: RoiBufs {
                a,
                b,
                c,
                d,
                labels,
                row_runs,
                max_pixels: m,
            },
        })
    }
}
