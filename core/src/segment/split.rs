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
//! ([`super::local::elongated_enough`]; no exemption for parts cut by the
//! frame border: it split border pieces of one fish apart, README), and
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

use super::local::{cut_by_border, elongated_enough};
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

/// Fraction of its area at the first level of the run that each part must
/// keep at the last (area stability, as in MSER). 0: each part need only
/// lie in its own part of the run's first level. 0.7 was measured and
/// dropped: it also refused the correct splits (seeds 1–8 and 12–16 then
/// changed by one object each).
pub const SPLIT_KEEP: f32 = 0.0;

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
/// `n`. Returns the new number of labels (at most
/// [`MAX_SPLIT_OBJECTS`]: labels are held as bytes).
#[allow(clippy::too_many_arguments)]
pub(crate) fn split_merged(
    sv: ImageView<'_>,
    roi: Roi,
    frame_size: (usize, usize),
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
        let Some((seeds, t_split)) = find_split(&o, labels, level, part, t_low, params, roi) else {
            continue;
        };
        grow_parts(&o, labels, part, seeds, t_split, t_low);
        if !parts_are_fish(part, bb, roi, seeds, params, frame_size) {
            stats.split_cancelled += 1;
            continue;
        }
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

/// Whether every grown part (ids `1..=seeds` in `part`, packed box `bb`)
/// would pass the final objects' shape test ([`elongated_enough`] or
/// [`cut_by_border`]): a split must leave fish, not a fish and a scrap.
fn parts_are_fish(
    part: &[u8],
    bb: Rect,
    roi: Roi,
    seeds: u8,
    params: &Params,
    (fw, fh): (usize, usize),
) -> bool {
    let bw = bb.w();
    let mut mom = [Moments::EMPTY; MAX_PARTS];
    for (y, prow) in part.chunks_exact(bw).take(bb.h()).enumerate() {
        let fy = roi.y + bb.y0 + y as u32;
        let mut x = 0;
        while x < prow.len() {
            let v = prow.get(x).copied().unwrap_or(0);
            let run = prow
                .get(x..)
                .map_or(0, |r| r.iter().position(|&q| q != v).unwrap_or(r.len()));
            if let Some(mm) = mom.get_mut((v as usize).wrapping_sub(1)) {
                let fx = roi.x + bb.x0 + x as u32;
                mm.add_run(fy, fx, fx + run as u32);
            }
            x += run.max(1);
        }
    }
    mom.iter().take(seeds as usize).all(|mm| {
        mm.area >= params.area_min as u64
            && (elongated_enough(mm, params.min_elongation) || cut_by_border(mm, fw, fh, params))
    })
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
    first: &mut [u8],
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
    let mut first_area = [0u32; MAX_PARTS + 1];
    let first = first.get_mut(..mb)?;
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
        // the qualifying parts: elongated (no border exemption)
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
        for l in sub.iter_mut() {
            *l = keep.get(*l as usize).copied().unwrap_or(0) as i32;
        }
        let mut area = [0u32; MAX_PARTS + 1];
        for (i, mm) in mom.iter().enumerate().take(nk as usize) {
            if let Some(a) = keep.get(i + 1).and_then(|&q| area.get_mut(q as usize)) {
                *a = mm.area.min(u32::MAX as u64) as u32;
            }
        }
        // stable: each part lies in its own part of the run's first level
        // and keeps at least SPLIT_KEEP of that part's area
        if run > 0 && stable(sub, first, &area, &first_area, parts) {
            run += 1;
        } else {
            run = 1;
            for (f, &l) in first.iter_mut().zip(sub.iter()) {
                *f = l as u8;
            }
            first_area = area;
        }
        if run >= SPLIT_STABLE {
            return Some((parts, t));
        }
    }
}

/// Whether the parts `1..=parts` of `sub` (areas `area`) each lie in a
/// different part of `first` and keep at least [`SPLIT_KEEP`] of its area
/// (`first_area`).
fn stable(
    sub: &[i32],
    first: &[u8],
    area: &[u32; MAX_PARTS + 1],
    first_area: &[u32; MAX_PARTS + 1],
    parts: u8,
) -> bool {
    let mut home = [0u8; MAX_PARTS + 1];
    for (&l, &f) in sub.iter().zip(first) {
        if l > 0 && f > 0 {
            if let Some(h) = home.get_mut(l as usize) {
                if *h == 0 {
                    *h = f;
                }
            }
        }
    }
    let mut used = [false; MAX_PARTS + 1];
    for q in 1..=parts as usize {
        let (Some(&h), Some(&a)) = (home.get(q), area.get(q)) else {
            return false;
        };
        let fa = first_area.get(h as usize).copied().unwrap_or(0);
        let seen = used.get_mut(h as usize);
        match seen {
            Some(u) if h > 0 && !*u => *u = true,
            _ => return false,
        }
        if (a as f32) < SPLIT_KEEP * fa as f32 {
            return false;
        }
    }
    true
}

/// Grows the seeds (`seeds` labels in `sub`, packed box) into part ids in
/// `part` (packed box): level by level from `t_split` down to `t_low`,
/// then over the whole object; each pixel joins the first part that
/// reaches it. Pixels not reached within the propagation's bound of
/// `bw + bh` rounds (only a winding object whose geodesic extent exceeds
/// it) stay part 0, which keeps the object's label; the f64 reference
/// does not model the bound.
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

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::vec;
    use std::vec::Vec;

    /// Labels `mask` (nonzero = object, components ≥ `area_min`), runs
    /// the split on the pixels `img`, returns (labels before, labels
    /// after, count after).
    fn run(img: &[u8], mask: &[u8], w: usize, h: usize, t_low: u8) -> (Vec<i32>, Vec<i32>, u32) {
        let p = Params::default();
        let mut labels = vec![0i32; w * h];
        let n = label_components(ImageView::packed(mask, w, h).unwrap(), &mut labels, |a| {
            a >= p.area_min
        })
        .unwrap();
        let before = labels.clone();
        let (mut l8, mut lv, mut pt) = (vec![0u8; w * h], vec![0u8; w * h], vec![0u8; w * h]);
        let bufs = SplitBufs {
            lab8: &mut l8,
            level: &mut lv,
            part: &mut pt,
        };
        let sv = ImageView::packed(img, w, h).unwrap();
        let mut st = SegmentStats::default();
        let m = split_merged(
            sv,
            Roi::new(0, 0, w as u32, h as u32),
            (w, h),
            &mut labels,
            n,
            t_low,
            &p,
            bufs,
            &mut st,
        );
        (before, labels, m)
    }

    /// Two 300 × 24 fish lying flank to flank, grey `g1` over `g2`, on
    /// water 20; `seam` darkens each fish's outer 4 rows by that much.
    fn pair(g1: u8, g2: u8, seam: u8) -> (Vec<u8>, Vec<u8>, usize, usize) {
        let (w, h) = (360, 80);
        let mut img = vec![20u8; w * h];
        let mut mask = vec![0u8; w * h];
        for y in 16..64 {
            for x in 30..330 {
                let (g, yy) = if y < 40 { (g1, y - 16) } else { (g2, y - 40) };
                let edge = !(4..20).contains(&yy);
                img[y * w + x] = if edge { g - seam } else { g };
                mask[y * w + x] = 255;
            }
        }
        (img, mask, w, h)
    }

    /// Fraction of the pixels of rows `ys` of the mask that carry the
    /// most frequent label there.
    fn purity(l: &[i32], w: usize, ys: core::ops::Range<usize>) -> (i32, f64) {
        let mut cnt = std::collections::HashMap::new();
        let mut tot = 0;
        for y in ys {
            for x in 30..330 {
                *cnt.entry(l[y * w + x]).or_insert(0usize) += 1;
                tot += 1;
            }
        }
        let (&lab, &c) = cnt.iter().max_by_key(|e| e.1).unwrap();
        (lab, c as f64 / tot as f64)
    }

    #[test]
    fn fish_of_different_brightness_are_split() {
        let (img, mask, w, _) = pair(90, 160, 30);
        let (_, l, n) = run(&img, &mask, w, 80, 40);
        assert_eq!(n, 2);
        // the cut runs halfway through the seam: the dim fish's 4 edge
        // rows there are reached by both parts at once (2 of its 24 rows)
        let (a, pa) = purity(&l, w, 16..40);
        let (b, pb) = purity(&l, w, 40..64);
        assert_ne!(a, b);
        assert!(pa > 0.9 && pb > 0.95, "{pa} {pb}");
    }

    #[test]
    fn equal_fish_split_at_their_darker_seam() {
        let (img, mask, w, _) = pair(120, 120, 50);
        let (_, l, n) = run(&img, &mask, w, 80, 40);
        assert_eq!(n, 2);
        let (a, pa) = purity(&l, w, 16..40);
        let (b, pb) = purity(&l, w, 40..64);
        assert_ne!(a, b);
        assert!(pa > 0.95 && pb > 0.95, "{pa} {pb}");
    }

    /// The limit: two flat fish of different brightness do not fall
    /// apart at any level (above the dim one only the bright one is left).
    #[test]
    fn flat_fish_of_different_brightness_stay_merged() {
        let (img, mask, w, _) = pair(90, 160, 0);
        let (before, l, n) = run(&img, &mask, w, 80, 40);
        assert_eq!(n, 1);
        assert_eq!(before, l);
    }

    #[test]
    fn one_fish_is_not_split() {
        // one 300 × 48 fish, brighter along its middle
        let (w, h) = (360, 80);
        let mut img = vec![20u8; w * h];
        let mut mask = vec![0u8; w * h];
        for y in 16..64usize {
            for x in 30..330 {
                img[y * w + x] = 160 - 3 * (y as i32 - 40).unsigned_abs() as u8;
                mask[y * w + x] = 255;
            }
        }
        let (before, l, n) = run(&img, &mask, w, h, 40);
        assert_eq!(n, 1);
        assert_eq!(before, l);
    }

    #[test]
    fn too_small_parts_are_not_split() {
        // the brighter fish holds fewer than area_min pixels
        let (mut img, mut mask, w, _) = pair(90, 160, 0);
        for y in 40..64 {
            for x in 100..330 {
                img[y * w + x] = 20;
                mask[y * w + x] = 0;
            }
        }
        let (before, l, n) = run(&img, &mask, w, 80, 40);
        assert_eq!(n, 1);
        assert_eq!(before, l);
    }

    proptest::proptest! {
        /// On random grey blobs: never panics, the objects' pixels stay
        /// objects, each pixel keeps its object's label or takes a new
        /// one (> n, ≤ the returned count), background stays 0.
        #[test]
        fn split_tiles_the_objects(seed in proptest::prelude::any::<u64>(), w in 20usize..140, h in 20usize..140, t_low in 0u8..80) {
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let mut img = vec![0u8; w * h];
            for _ in 0..6 {
                let (cx, cy) = ((next() % w as u64) as i64, (next() % h as u64) as i64);
                let (rx, ry) = (5 + (next() % 60) as i64, 2 + (next() % 20) as i64);
                let g = (next() % 256) as u8;
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        let (dx, dy) = (x - cx, y - cy);
                        if dx * dx * ry * ry + dy * dy * rx * rx <= rx * rx * ry * ry {
                            let v = &mut img[y as usize * w + x as usize];
                            *v = (*v).max(g.wrapping_add((next() % 9) as u8));
                        }
                    }
                }
            }
            let mask: Vec<u8> = img.iter().map(|&v| if v > t_low { 255 } else { 0 }).collect();
            let p = Params { area_min: 30, min_elongation: 1.5, ..Params::default() };
            let mut labels = vec![0i32; w * h];
            let n = label_components(ImageView::packed(&mask, w, h).unwrap(), &mut labels, |a| a >= p.area_min).unwrap();
            let before = labels.clone();
            let (mut l8, mut lv, mut pt) = (vec![0u8; w * h], vec![0u8; w * h], vec![0u8; w * h]);
            let bufs = SplitBufs { lab8: &mut l8, level: &mut lv, part: &mut pt };
            let sv = ImageView::packed(&img, w, h).unwrap();
            let mut st = SegmentStats::default();
            let m = split_merged(sv, Roi::new(0, 0, w as u32, h as u32), (w, h), &mut labels, n, t_low, &p, bufs, &mut st);
            proptest::prop_assert!(m >= n);
            proptest::prop_assert_eq!(m - n, st.split);
            for (&b, &a) in before.iter().zip(&labels) {
                proptest::prop_assert_eq!(b == 0, a == 0);
                proptest::prop_assert!(a == b || (a as u32 > n && a as u32 <= m));
            }
            // every new label is one 8-connected piece of a single object
            let mut owner = std::collections::HashMap::new();
            for (&b, &a) in before.iter().zip(&labels) {
                if a as u32 > n {
                    proptest::prop_assert_eq!(*owner.entry(a).or_insert(b), b);
                }
            }
        }
    }
}
