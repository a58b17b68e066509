//! Component-tree split of merged objects (beyond the paper; Section III.D
//! outputs one object per connected mask, so two fish that touch become
//! one object).
//!
//! For every final object of a region (after closing and opening), the
//! threshold is raised from ⌊τ_low⌋ upwards in at most [`SPLIT_LEVELS`]
//! steps over the object's own grey-level range (the pixels the
//! thresholds of eq. (1) saw). When at some level the object's pixels
//! above it fall into at least two 8-connected components that each hold
//! at least `area_min` pixels (θ_A^L, eq. (4)) and each are elongated
//! ([`super::local::elongated_enough`]) or cut by the frame border, and
//! this holds for [`SPLIT_STABLE`] consecutive levels, the object is two
//! (or more) fish: fish of different reflectivity separate at a level
//! between their brightnesses, fish of equal brightness at the darker seam
//! where their flanks meet — neither of which a distance transform sees.
//! The parts of the highest of those levels are the seeds; they grow back
//! level by level down to ⌊τ_low⌋ and then over the whole original mask,
//! each pixel joining the part that reaches it first (8-connected
//! propagation inside the level's set), so the parts tile the original
//! mask exactly.
//!
//! Memory: no extra workspace — the region's `i32` label buffer is free
//! while its labels are held as bytes (so at most 254 objects per region
//! are examined; with more, nothing is split), and two of the region's
//! byte masks hold a level's mask and the parts. Stack: one bounding box
//! per object (4 KiB).

use super::local::elongated_enough;
use super::SegmentStats;
use crate::image::{ImageView, Roi};
use crate::label::{label_components, Moments};
use crate::params::Params;

/// Most threshold levels tried per object (the step is the object's range
/// `[⌊τ_low⌋, max]` divided by this, at least one grey level).
pub const SPLIT_LEVELS: u32 = 16;

/// Consecutive levels at which the object must stay in ≥ 2 qualifying
/// parts before it is split.
pub const SPLIT_STABLE: u32 = 3;

/// Most seed parts per split (further qualifying parts grow into these).
pub const MAX_PARTS: usize = 8;

/// Most objects per region the split examines (labels held as bytes).
pub const MAX_SPLIT_OBJECTS: u32 = 254;

/// The byte buffers the split borrows from the region's workspace, each at
/// least `rw · rh` bytes.
pub(crate) struct SplitBufs<'a> {
    /// The region's labels as bytes.
    pub lab8: &'a mut [u8],
    /// One level's mask (bounding box of one object, packed).
    pub level: &'a mut [u8],
    /// Part ids (bounding box of one object, packed).
    pub part: &'a mut [u8],
}

/// Splits the merged objects among the `n` labelled objects of `labels`
/// (`rw × rh`, ROI `roi` of the frame; `sv` the pixels the
/// thresholds saw). Parts keep the object's label or get new labels after
/// `n`. Returns the new number of labels (never more than
/// [`MAX_SPLIT_OBJECTS`] + 1).
#[allow(clippy::too_many_arguments)]
pub(crate) fn split_merged(
    sv: ImageView<'_>,
    roi: Roi,
    labels: &mut [i32],
    n: u32,
    t_low: u8,
    params: &Params,
    bufs: SplitBufs<'_>,
    stats: &mut SegmentStats,
) -> u32 {
    let (rw, rh) = (sv.width(), sv.height());
    let m = rw * rh;
    if n == 0 || n > MAX_SPLIT_OBJECTS || labels.len() < m {
        return n;
    }
    let (Some(lab8), Some(level), Some(part)) = (
        bufs.lab8.get_mut(..m),
        bufs.level.get_mut(..m),
        bufs.part.get_mut(..m),
    ) else {
        return n;
    };
    // labels as bytes, bounding boxes [x0, y0, x1, y1) per label
    let mut boxes = [[u32::MAX, u32::MAX, 0u32, 0u32]; MAX_SPLIT_OBJECTS as usize];
    for (j, (lrow, brow)) in labels
        .chunks_exact(rw)
        .zip(lab8.chunks_exact_mut(rw))
        .enumerate()
    {
        for (i, (&l, b)) in lrow.iter().zip(brow.iter_mut()).enumerate() {
            *b = if l > 0 && l as u32 <= n { l as u8 } else { 0 };
            if let Some(bx) = boxes.get_mut((*b as usize).wrapping_sub(1)) {
                bx[0] = bx[0].min(i as u32);
                bx[1] = bx[1].min(j as u32);
                bx[2] = bx[2].max(i as u32 + 1);
                bx[3] = bx[3].max(j as u32 + 1);
            }
        }
    }
    let mut next = n;
    for k in 1..=n as u8 {
        let Some(&[x0, y0, x1, y1]) = boxes.get(k as usize - 1) else {
            break;
        };
        if x1 <= x0 || y1 <= y0 || next >= MAX_SPLIT_OBJECTS {
            continue;
        }
        let bb = Rect { x0, y0, x1, y1 };
        let o = Obj {
            sv,
            lab8: &*lab8,
            rw,
            k,
            bb,
        };
        let Some((seeds, t_split)) = find_split(&o, labels, level, t_low, params, roi) else {
            continue;
        };
        grow_parts(&o, labels, part, seeds, t_split, t_low);
        // relabel: part 1 keeps k, the others get new labels
        let bw = bb.w();
        let mut map = [k; MAX_PARTS + 1];
        for p in 2..=seeds as usize {
            if next < MAX_SPLIT_OBJECTS {
                next += 1;
                if let Some(v) = map.get_mut(p) {
                    *v = next as u8;
                }
                stats.split += 1;
            }
        }
        for y in y0..y1 {
            let (r0, p0) = (y as usize * rw, (y - y0) as usize * bw);
            let lrow = lab8.get_mut(r0 + x0 as usize..r0 + x1 as usize);
            let prow = part.get(p0..p0 + bw);
            if let (Some(lrow), Some(prow)) = (lrow, prow) {
                for (l, &p) in lrow.iter_mut().zip(prow) {
                    if *l == k {
                        *l = map.get(p as usize).copied().unwrap_or(k);
                    }
                }
            }
        }
    }
    for (l, &b) in labels.iter_mut().zip(lab8.iter()) {
        *l = b as i32;
    }
    next
}

/// A bounding box `[x0, x1) × [y0, y1)` in ROI coordinates.
#[derive(Clone, Copy)]
struct Rect {
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
}

impl Rect {
    fn w(&self) -> usize {
        (self.x1 - self.x0) as usize
    }
    fn h(&self) -> usize {
        (self.y1 - self.y0) as usize
    }
}

/// One object of a region: label `k` of `lab8` (`rw` wide), box `bb`.
struct Obj<'a> {
    sv: ImageView<'a>,
    lab8: &'a [u8],
    rw: usize,
    k: u8,
    bb: Rect,
}

impl Obj<'_> {
    /// Row `y` (box coordinates) of the object: its labels and pixels.
    fn row(&self, y: usize) -> (&[u8], &[u8]) {
        let yy = self.bb.y0 as usize + y;
        let (x0, x1) = (self.bb.x0 as usize, self.bb.x1 as usize);
        let l = self
            .lab8
            .get(yy * self.rw + x0..yy * self.rw + x1)
            .unwrap_or(&[]);
        let p = self.sv.row(yy).get(x0..x1).unwrap_or(&[]);
        (l, p)
    }

    /// Writes into `out` (packed box) 255 where the object's pixel is
    /// above `t`, else 0.
    fn level_mask(&self, t: u8, out: &mut [u8]) {
        let bw = self.bb.w();
        for (y, orow) in out.chunks_exact_mut(bw).take(self.bb.h()).enumerate() {
            let (l, p) = self.row(y);
            for ((o, &lv), &pv) in orow.iter_mut().zip(l).zip(p) {
                *o = if lv == self.k && pv > t { 255 } else { 0 };
            }
        }
    }
}

/// The level at which the object falls into stable qualifying parts:
/// `(number of seed parts, level)`, the seeds labelled `1..=parts` in
/// `sub` (packed box; other components 0).
fn find_split(
    o: &Obj<'_>,
    sub: &mut [i32],
    level: &mut [u8],
    t_low: u8,
    params: &Params,
    roi: Roi,
) -> Option<(u8, u8)> {
    let (bw, bh) = (o.bb.w(), o.bb.h());
    let mb = bw * bh;
    let level = level.get_mut(..mb)?;
    let sub = sub.get_mut(..mb)?;
    // the object's grey-level range
    let mut vmax = 0u8;
    for y in 0..bh {
        let (l, p) = o.row(y);
        for (&lv, &pv) in l.iter().zip(p) {
            if lv == o.k {
                vmax = vmax.max(pv);
            }
        }
    }
    if vmax <= t_low {
        return None;
    }
    let step = ((vmax - t_low) as u32).div_ceil(SPLIT_LEVELS).max(1) as u8;
    let amin = params.area_min;
    let mut run = 0u32;
    let mut t = t_low;
    loop {
        t = t.checked_add(step)?;
        if t >= vmax {
            return None;
        }
        o.level_mask(t, level);
        let view = ImageView::packed(level, bw, bh).ok()?;
        let nk = label_components(view, sub, |a| a >= amin).ok()?;
        if nk < 2 {
            if nk == 0 {
                return None;
            }
            run = 0;
            continue;
        }
        // the qualifying parts: elongated or cut by the frame border
        let mut mom = [Moments::EMPTY; MAX_PARTS];
        for (y, lrow) in sub.chunks_exact(bw).enumerate() {
            let fy = roi.y + o.bb.y0 + y as u32;
            for (x, &l) in lrow.iter().enumerate() {
                if let Some(mm) = mom.get_mut((l as usize).wrapping_sub(1)) {
                    let fx = roi.x + o.bb.x0 + x as u32;
                    mm.add_run(fy, fx, fx + 1);
                }
            }
        }
        let mut keep = [0u8; MAX_PARTS + 1];
        let mut parts = 0u8;
        for (i, mm) in mom.iter().enumerate().take(nk as usize) {
            if elongated_enough(mm, params.min_elongation) {
                parts += 1;
                if let Some(v) = keep.get_mut(i + 1) {
                    *v = parts;
                }
            }
        }
        if parts < 2 {
            run = 0;
            continue;
        }
        run += 1;
        if run >= SPLIT_STABLE {
            for l in sub.iter_mut() {
                *l = keep.get(*l as usize).copied().unwrap_or(0) as i32;
            }
            return Some((parts, t));
        }
    }
}

/// Grows the seeds (`seeds` labels in `sub`, packed box) into part ids in
/// `part` (packed box): level by level from `t_split` down to `t_low`,
/// then over the whole object; each pixel joins the first part that
/// reaches it. Pixels never reached (cannot happen: the object is
/// connected) stay part 0, which keeps the object's label.
fn grow_parts(o: &Obj<'_>, sub: &[i32], part: &mut [u8], seeds: u8, t_split: u8, t_low: u8) {
    let (bw, bh) = (o.bb.w(), o.bb.h());
    let mb = bw * bh;
    let Some(part) = part.get_mut(..mb) else {
        return;
    };
    for (p, &s) in part.iter_mut().zip(sub) {
        *p = if s > 0 && s <= seeds as i32 {
            s as u8
        } else {
            0
        };
    }
    let step = ((t_split - t_low) as u32).div_ceil(SPLIT_LEVELS).max(1) as u8;
    let mut t = t_split;
    loop {
        let floor = t <= t_low;
        t = if floor {
            0
        } else {
            t.saturating_sub(step).max(t_low)
        };
        propagate(o, part, if floor { None } else { Some(t) });
        if floor {
            break;
        }
    }
}

/// Grows the part ids into the object's unassigned pixels above `t` (all
/// of the object's pixels for `None`) one 8-neighbour ring per round (a
/// breadth-first, geodesic growth: a pixel joins the part that reaches it
/// in the fewest steps; on a tie the first in raster order of its
/// neighbours), until nothing changes (at most `bw + bh` rounds). Pixels
/// taken in the current round carry [`FRESH`] and do not spread in it.
fn propagate(o: &Obj<'_>, part: &mut [u8], t: Option<u8>) {
    let (bw, bh) = (o.bb.w(), o.bb.h());
    for _ in 0..bw + bh {
        let mut changed = false;
        for y in 0..bh {
            let (l, p) = o.row(y);
            for (x, (&lv, &pv)) in l.iter().zip(p).enumerate() {
                let i = y * bw + x;
                if lv != o.k || t.is_some_and(|t| pv <= t) || part.get(i).copied() != Some(0) {
                    continue;
                }
                if let Some(v) = settled_neighbour(part, bw, bh, x, y) {
                    if let Some(q) = part.get_mut(i) {
                        *q = v | FRESH;
                        changed = true;
                    }
                }
            }
        }
        for q in part.iter_mut() {
            *q &= !FRESH;
        }
        if !changed {
            break;
        }
    }
}

/// Marks a part id taken in the current growth round.
const FRESH: u8 = 0x80;

/// The part of the first 8-neighbour of `(x, y)` (box coordinates) that
/// was settled before the current round.
#[inline]
fn settled_neighbour(part: &[u8], bw: usize, bh: usize, x: usize, y: usize) -> Option<u8> {
    for (dx, dy) in [
        (-1, -1),
        (0, -1),
        (1, -1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (0, 1),
        (1, 1),
    ] {
        let (nx, ny) = (x as isize + dx, y as isize + dy);
        if nx < 0 || ny < 0 || nx >= bw as isize || ny >= bh as isize {
            continue;
        }
        let v = part
            .get(ny as usize * bw + nx as usize)
            .copied()
            .unwrap_or(0);
        if v != 0 && v & FRESH == 0 {
            return Some(v);
        }
    }
    None
}
