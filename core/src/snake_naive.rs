//! The tail snake as first written (direct 5 × 5 reads for every
//! candidate, every sweep run): the oracle the memoised, cycle-detecting
//! [`super::tail_snake`] must match exactly.

#![allow(clippy::too_many_arguments, clippy::needless_range_loop)]

use super::{SnakeParams, SnakeResult, SNAKE_POINTS};
use crate::image::ImageView;

fn smooth(img: &ImageView<'_>, x: i32, y: i32) -> f32 {
    let mut s = 0u32;
    for dy in -2..=2 {
        for dx in -2..=2 {
            s += img.get_clamped((x + dx) as isize, (y + dy) as isize) as u32;
        }
    }
    s as f32 / 25.0
}

fn grad(img: &ImageView<'_>, x: i32, y: i32) -> f32 {
    let gx = smooth(img, x + 1, y) - smooth(img, x - 1, y);
    let gy = smooth(img, x, y + 1) - smooth(img, x, y - 1);
    libm::sqrtf(gx * gx + gy * gy)
}

pub fn tail_snake_naive(
    img: &ImageView<'_>,
    end: (f32, f32),
    dir: (f32, f32),
    h_o: f32,
    body_mean: f32,
    bg: (f32, f32),
    fin: f32,
    p: &SnakeParams,
) -> SnakeResult {
    let nrm = libm::sqrtf(dir.0 * dir.0 + dir.1 * dir.1);
    let (ux, uy) = if nrm > 1e-6 && nrm.is_finite() {
        (dir.0 / nrm, dir.1 / nrm)
    } else {
        (1.0, 0.0)
    };
    let h_o = if h_o.is_finite() {
        h_o.clamp(4.0, 4096.0)
    } else {
        4.0
    };
    let radius = h_o / 4.0;
    let (cx, cy) = (end.0 + ux * radius, end.1 + uy * radius);
    let contrast = (body_mean - bg.0).max(0.0);
    let mut above = p.level_fraction * contrast;
    if fin > 0.0 && fin.is_finite() {
        above = above.min(p.fin_level_fraction * fin);
    }
    // on a half-grey-level grid: the decision does not hang on rounding
    let level = micromath::F32(2.0 * (bg.0 + above.max(3.0 * bg.1 / 5.0 + 1.0)))
        .round()
        .0
        * 0.5;
    let mut pts = [(0.0f32, 0.0f32); SNAKE_POINTS];
    for (i, q) in pts.iter_mut().enumerate() {
        let a = i as f32 * core::f32::consts::TAU / SNAKE_POINTS as f32;
        // on whole pixels: every later position is a whole-pixel move, so
        // the pixels the snake samples do not hang on rounding
        *q = (
            libm::roundf(cx + radius * libm::cosf(a)),
            libm::roundf(cy + radius * libm::sinf(a)),
        );
    }
    let reach = p.reach.clamp(1, 4) as i32;
    let (w, h) = (img.width() as f32, img.height() as f32);
    let mut sweeps = 0;
    for _ in 0..p.iterations.min(1000) {
        sweeps += 1;
        let mut moved = 0;
        // mean spacing d̄
        let mut per = 0.0;
        for i in 0..SNAKE_POINTS {
            let a = pts[i];
            let b = pts[(i + 1) % SNAKE_POINTS];
            per += libm::sqrtf((a.0 - b.0) * (a.0 - b.0) + (a.1 - b.1) * (a.1 - b.1));
        }
        let dbar = (per / SNAKE_POINTS as f32).max(0.5);
        // centroid for the outward normal
        let (mut gx, mut gy) = (0.0, 0.0);
        for q in pts.iter() {
            gx += q.0;
            gy += q.1;
        }
        let (gx, gy) = (gx / SNAKE_POINTS as f32, gy / SNAKE_POINTS as f32);
        for i in 0..SNAKE_POINTS {
            let prev = pts[(i + SNAKE_POINTS - 1) % SNAKE_POINTS];
            let next = pts[(i + 1) % SNAKE_POINTS];
            let cur = pts[i];
            // outward normal: perpendicular to the chord, away from the centroid
            let (tx, ty) = (next.0 - prev.0, next.1 - prev.1);
            let (mut nx, mut ny) = (ty, -tx);
            if nx * (cur.0 - gx) + ny * (cur.1 - gy) < 0.0 {
                nx = -nx;
                ny = -ny;
            }
            let nn = libm::sqrtf(nx * nx + ny * ny);
            if nn > 1e-6 {
                nx /= nn;
                ny /= nn;
            }
            let mut gmax = 1e-3f32;
            // (x, y, internal energy, |∇I|, pressure)
            let mut cand = [(0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32); 81];
            let mut nc = 0;
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let q = (cur.0 + dx as f32, cur.1 + dy as f32);
                    if q.0 < 0.0 || q.1 < 0.0 || q.0 > w - 1.0 || q.1 > h - 1.0 {
                        continue;
                    }
                    // never behind the end (the body side)
                    if (q.0 - end.0) * ux + (q.1 - end.1) * uy < 0.0 {
                        continue;
                    }
                    let (qx, qy) = (q.0 as i32, q.1 as i32);
                    let g = grad(img, qx, qy);
                    gmax = gmax.max(g);
                    let inside = if smooth(img, qx, qy) >= level {
                        1.0
                    } else {
                        -1.0
                    };
                    let push = (dx as f32 * nx + dy as f32 * ny) / reach as f32;
                    let dc = libm::sqrtf(
                        (q.0 - prev.0) * (q.0 - prev.0) + (q.1 - prev.1) * (q.1 - prev.1),
                    );
                    let cont = (dbar - dc).abs() / dbar;
                    let (kx, ky) = (prev.0 - 2.0 * q.0 + next.0, prev.1 - 2.0 * q.1 + next.1);
                    let curv = (kx * kx + ky * ky) / (dbar * dbar);
                    if let Some(c) = cand.get_mut(nc) {
                        *c = (
                            q.0,
                            q.1,
                            p.alpha * cont + p.beta * curv,
                            g,
                            -p.kappa * inside * push,
                        );
                        nc += 1;
                    }
                }
            }
            let mut best = (f32::INFINITY, cur);
            for c in cand.iter().take(nc) {
                let e = c.2 - p.gamma * c.3 / gmax + c.4;
                if e < best.0 {
                    best = (e, (c.0, c.1));
                }
            }
            if best.0.is_finite() && best.1 != cur {
                pts[i] = best.1;
                moved += 1;
            }
        }
        if moved == 0 {
            break;
        }
    }
    let mut res = SnakeResult {
        points: pts,
        accepted: false,
        far_t: 0.0,
        area: 0.0,
        inside_fraction: 0.0,
        level,
        sweeps,
    };
    // shoelace area
    let mut a2 = 0.0;
    for i in 0..SNAKE_POINTS {
        let a = pts[i];
        let b = pts[(i + 1) % SNAKE_POINTS];
        a2 += a.0 * b.1 - b.0 * a.1;
    }
    res.area = (a2 * 0.5).abs();
    // rasterise the polygon inside its bounding box
    let (mut x0, mut y0, mut x1, mut y1) = (
        f32::INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NEG_INFINITY,
    );
    for q in pts.iter() {
        x0 = x0.min(q.0);
        y0 = y0.min(q.1);
        x1 = x1.max(q.0);
        y1 = y1.max(q.1);
    }
    if !(x0.is_finite() && y0.is_finite() && x1.is_finite() && y1.is_finite()) {
        return res;
    }
    let (xa, ya) = (x0.max(0.0) as i32, y0.max(0.0) as i32);
    let (xb, yb) = (x1.min(w - 1.0) as i32, y1.min(h - 1.0) as i32);
    let mut n_in = 0u32;
    let mut n_hi = 0u32;
    let mut far = f32::NEG_INFINITY;
    let mut near = f32::INFINITY;
    for y in ya..=yb {
        for x in xa..=xb {
            if !point_in_polygon(&pts, x as f32, y as f32) {
                continue;
            }
            n_in += 1;
            let t = (x as f32 - end.0) * ux + (y as f32 - end.1) * uy;
            if smooth(img, x, y) >= level {
                n_hi += 1;
                far = far.max(t);
                near = near.min(t);
            }
        }
    }
    if n_in == 0 {
        return res;
    }
    res.inside_fraction = n_hi as f32 / n_in as f32;
    let min_area = 0.25 * radius * radius * core::f32::consts::PI;
    res.accepted = res.area >= min_area
        && res.inside_fraction >= 0.6
        && near <= radius
        && far.is_finite()
        && far > 1.0;
    if res.accepted {
        res.far_t = far;
    }
    res
}

/// Even–odd rule point-in-polygon test (the per-pixel form of
/// [`super::fill_polygon`]).
pub fn point_in_polygon(pts: &[(f32, f32); SNAKE_POINTS], x: f32, y: f32) -> bool {
    let mut inside = false;
    let mut j = SNAKE_POINTS - 1;
    for i in 0..SNAKE_POINTS {
        let (xi, yi) = pts[i];
        let (xj, yj) = pts[j];
        if (yi > y) != (yj > y) {
            let xc = xj + (y - yj) * (xi - xj) / (yi - yj);
            if x < xc {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}
