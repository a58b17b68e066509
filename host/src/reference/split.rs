//! Reference of the component-tree split of merged objects
//! (`fishtrack_core::segment::split`, beyond the paper), written for
//! clarity: level sets as pixel lists, `imageproc` components, growth as a
//! breadth-first search one ring per round.
//!
//! Not modelled: the core's caps (254 objects per region, 8 seed parts,
//! `bw + bh` growth rounds per level).

use super::segment::{components, pca};
use fishtrack_core::segment::split::{SPLIT_KEEP, SPLIT_LEVELS, SPLIT_STABLE};
use fishtrack_core::Params;
use image::{GrayImage, Luma};
use std::collections::{HashMap, HashSet};

/// Splits one object `comp` (ROI pixels, raster order) of a `rw × rh` ROI
/// whose thresholded pixels are `seen`, `t_low` = ⌊τ_low⌋. Returns its
/// parts (one part, `comp` itself, when it is not split), each in raster
/// order; the first keeps the object's place. `cut(part)`: whether the
/// frame border cuts a part.
pub fn split_object(
    comp: &[(u32, u32)],
    seen: &GrayImage,
    t_low: u8,
    p: &Params,
    cut: impl Fn(&[(u32, u32)]) -> bool,
) -> Vec<Vec<(u32, u32)>> {
    let whole = vec![comp.to_vec()];
    let v = |q: &(u32, u32)| seen.get_pixel(q.0, q.1).0[0];
    let vmax = comp.iter().map(v).max().unwrap_or(0);
    if vmax <= t_low {
        return whole;
    }
    let (rw, rh) = seen.dimensions();
    let e = p.min_elongation as f64;
    let step = ((vmax - t_low) as u32).div_ceil(SPLIT_LEVELS).max(1);
    let mut run = 0;
    let mut first: Vec<HashSet<(u32, u32)>> = Vec::new();
    let mut t = t_low as u32;
    let seeds = loop {
        t += step;
        if t >= vmax as u32 {
            return whole;
        }
        let mut level = GrayImage::new(rw, rh);
        for q in comp.iter().filter(|q| v(q) as u32 > t) {
            level.put_pixel(q.0, q.1, Luma([255]));
        }
        let big: Vec<Vec<(u32, u32)>> = components(&level)
            .into_iter()
            .filter(|c| c.len() >= p.area_min as usize)
            .collect();
        if big.is_empty() {
            return whole;
        }
        // the seed parts: elongated, among the first 8 big components
        let parts: Vec<Vec<(u32, u32)>> = big
            .into_iter()
            .take(8)
            .filter(|c| {
                let (_, _, _, l1, l2) = pca(c);
                e <= 1.0 || l1 >= e * e * l2
            })
            .collect();
        if parts.len() < 2 {
            run = 0;
            continue;
        }
        // stable: each part inside its own part of the run's first level,
        // keeping SPLIT_KEEP of its area
        let homes: Vec<Option<usize>> = parts
            .iter()
            .map(|c| first.iter().position(|f| f.contains(&c[0])))
            .collect();
        let distinct = homes.iter().flatten().collect::<HashSet<_>>().len() == parts.len();
        let kept = parts.iter().zip(&homes).all(|(c, h)| {
            h.is_some_and(|h| c.len() as f64 >= SPLIT_KEEP as f64 * first[h].len() as f64)
        });
        if run > 0 && distinct && kept {
            run += 1;
        } else {
            run = 1;
            first = parts.iter().map(|c| c.iter().copied().collect()).collect();
        }
        if run >= SPLIT_STABLE {
            break parts;
        }
    };
    // growth, level by level down to t_low, then over the whole object
    let mut owner: HashMap<(u32, u32), usize> = HashMap::new();
    for (k, s) in seeds.iter().enumerate() {
        for &q in s {
            owner.insert(q, k);
        }
    }
    let step2 = (t - t_low as u32).div_ceil(SPLIT_LEVELS).max(1);
    let mut tl = Some(t);
    while let Some(cur) = tl {
        let (open_above, next) = if cur <= t_low as u32 {
            (None, None)
        } else {
            let nt = cur.saturating_sub(step2).max(t_low as u32);
            (Some(nt), Some(nt))
        };
        grow(comp, &mut owner, |q| {
            open_above.is_none_or(|t| v(q) as u32 > t)
        });
        tl = next;
    }
    let mut out = vec![Vec::new(); seeds.len()];
    for q in comp {
        // (never reached pixels cannot occur; they would stay with part 1)
        out[owner.get(q).copied().unwrap_or(0)].push(*q);
    }
    // every part must pass the final shape test (elongated, or cut by the
    // frame border: `cut(part)`), else the object stays whole
    let fish = |c: &Vec<(u32, u32)>| {
        let (_, _, _, l1, l2) = pca(c);
        c.len() >= p.area_min as usize && (e <= 1.0 || l1 >= e * e * l2 || cut(c))
    };
    if out.iter().all(fish) {
        out
    } else {
        whole
    }
}

/// Grows the owners into the open unowned pixels of `comp`, one
/// 8-neighbour ring per round; a pixel takes the owner of its first owned
/// neighbour in the order NW, N, NE, W, E, SW, S, SE.
fn grow(
    comp: &[(u32, u32)],
    owner: &mut HashMap<(u32, u32), usize>,
    open: impl Fn(&(u32, u32)) -> bool,
) {
    loop {
        let mut taken = Vec::new();
        for q in comp.iter().filter(|q| !owner.contains_key(q) && open(q)) {
            let (x, y) = (q.0 as i64, q.1 as i64);
            let first = [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ]
            .iter()
            .filter(|(dx, dy)| x + dx >= 0 && y + dy >= 0)
            .find_map(|(dx, dy)| owner.get(&((x + dx) as u32, (y + dy) as u32)));
            if let Some(&k) = first {
                taken.push((*q, k));
            }
        }
        if taken.is_empty() {
            return;
        }
        owner.extend(taken);
    }
}
