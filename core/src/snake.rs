//! Fish-tail end compensation with a snake (Section IV.D.1, Fig. 10).
//!
//! A closed active contour of [`SNAKE_POINTS`] points starts as a circle of
//! diameter `h_o / 2` placed beside the mismatched end along the principal
//! axis (touching the end). It evolves with the greedy algorithm of Williams
//! & Shah (each point moves to the lowest-energy position of its
//! `(2k+1)²` neighbourhood, at most `iterations` sweeps) under
//! - continuity `α·|d̄ − |pᵢ − pᵢ₋₁|| / d̄` and curvature
//!   `β·|pᵢ₋₁ − 2pᵢ + pᵢ₊₁|² / d̄²` (internal energy),
//! - edge attraction `−γ·|∇I| / max|∇I|` on a 5 × 5 box-smoothed image,
//! - a region pressure `κ`: outward over pixels at or above the tail level
//!   `τ`, inward over darker ones (a balloon force signed by the region test,
//!   so the contour grows over a dim tail and collapses over background).
//!
//! Points may not cross back behind the end (the body side). The level `τ`
//! sits between the local background (median and MAD of a ring around the
//! object's box) and the body mean, at most half the fin's own contrast
//! when [`end_probe`] measured it (rounded to half a grey level, so the
//! float reference makes the same pixel decisions). The enclosed region is accepted when it
//! is large enough, mostly at or above `τ`, and within the closing radius
//! (`h_o/4`) of the end: then, as the morphological closing of body and
//! region would, it extends the body to the region's far end along the axis.
//! The caller recomputes the end point from [`SnakeResult::far_t`].
//!
//! Memory bound: `SNAKE_POINTS` points, a 512-sample ring, the hashes of
//! the last 64 contours (512 B), one contour under test and a 64 × 64 torus
//! of memoised 5 × 5 box sums and gradients (40 KiB) on the stack. Work: at
//! most `iterations · SNAKE_POINTS · (2k+1)²` candidates of a memoised sum
//! and gradient each, 25 pixel reads per distinct pixel the contour
//! visits, and about 5 per pixel of the final contour's box (scan
//! conversion with sliding box sums). A sweep is a function of the contour
//! alone, so a contour whose hash repeats one of the last 64 ends the loop
//! once the repeat is confirmed on the contour itself: the final contour of
//! a cycle is known without running the rest. On the default hauls every snake that runs reaches the sweep
//! bound, and about half of them do so in cycles of period 12–56.

use crate::image::{ImageView, Roi};

/// Number of contour points.
pub const SNAKE_POINTS: usize = 32;

/// Sweeps whose contour hashes are remembered to detect a contour that
/// cycles (periods `2 ..= HISTORY − 1`, each confirmed on the contour
/// itself before it is trusted).
const HISTORY: usize = 64;

#[cfg(test)]
std::thread_local! {
    /// Cycles of period > 8 confirmed on this thread (the tests check that
    /// long periods are exercised).
    static LONG_CYCLES: core::cell::Cell<u32> = const { core::cell::Cell::new(0) };
}

/// A contour of the snake.
type Contour = [(f32, f32); SNAKE_POINTS];

/// FNV-1a over the contour's coordinates (their bit patterns).
fn contour_hash(pts: &Contour) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for q in pts.iter() {
        for v in [q.0.to_bits(), q.1.to_bits()] {
            h = (h ^ v as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// Most background samples taken around the object's box.
const RING_SAMPLES: usize = 512;

/// Snake weights and bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SnakeParams {
    /// α — continuity weight.
    pub alpha: f32,
    /// β — curvature weight.
    pub beta: f32,
    /// γ — edge-attraction weight.
    pub gamma: f32,
    /// κ — region pressure weight.
    pub kappa: f32,
    /// Sweeps over all points (iteration bound).
    pub iterations: u16,
    /// Neighbourhood half-size k (candidates `(2k+1)²`).
    pub reach: u8,
    /// Fraction of the background-to-body contrast that sets the tail level τ.
    pub level_fraction: f32,
    /// When the fin's own contrast just beyond the end is known
    /// ([`end_probe`]), τ sits at most this fraction of it above the
    /// background: a dim fin (0.1–0.3 of the body's contrast) stays above τ.
    pub fin_level_fraction: f32,
}

impl Default for SnakeParams {
    fn default() -> Self {
        SnakeParams {
            alpha: 0.3,
            beta: 0.2,
            gamma: 0.5,
            kappa: 2.0,
            iterations: 200,
            reach: 2,
            level_fraction: 0.15,
            fin_level_fraction: 0.5,
        }
    }
}

/// What the snake found beside one end.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SnakeResult {
    /// Final contour.
    pub points: [(f32, f32); SNAKE_POINTS],
    /// Region accepted as a missing tail.
    pub accepted: bool,
    /// Far extent of the accepted region beyond the end, along the axis, pixels.
    pub far_t: f32,
    /// Enclosed area, pixels.
    pub area: f32,
    /// Fraction of enclosed pixels at or above τ.
    pub inside_fraction: f32,
    /// Tail level τ used.
    pub level: f32,
    /// Sweeps run.
    pub sweeps: u16,
}

/// 5 × 5 box sum at `(x, y)` (replicated border): at most 25 · 255.
fn box_sum(img: &ImageView<'_>, x: i32, y: i32) -> u32 {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (xl, yl) = (x as i64, y as i64);
    let mut s = 0u32;
    if xl >= 2 && yl >= 2 && xl + 2 < w && yl + 2 < h {
        // wholly inside: five row slices
        let xa = (xl - 2) as usize;
        for yy in (yl - 2)..=(yl + 2) {
            if let Some(r) = img.row(yy as usize).get(xa..xa + 5) {
                for &v in r {
                    s += v as u32;
                }
            }
        }
        return s;
    }
    for dy in -2..=2 {
        for dx in -2..=2 {
            s += img.get_clamped((x + dx) as isize, (y + dy) as isize) as u32;
        }
    }
    s
}

/// Side of the torus of memoised box sums and gradients, a power of two:
/// pixel `(x, y)` has the slot `(x mod 64, y mod 64)`, tagged with
/// `(x div 64, y div 64)` (40 KiB of stack in all).
const CACHE_SIDE: usize = 64;

/// Coordinates (plus one) the memo serves: tag halves below 255, so the
/// tag `0xFFFF` marks an empty slot. Pixels beyond (frames wider or
/// taller than 16 319 px) are computed afresh.
const TAG_LIMIT: u32 = 255 * CACHE_SIDE as u32;

/// An empty slot.
const UNSET: u16 = u16::MAX;

/// The 5 × 5 box sums and their gradients the snake reads, each computed
/// once while it stays in its slot: the greedy sweeps revisit the same
/// pixels many times (on the hauls every snake runs its whole sweep
/// bound), and every energy term reads the box-smoothed image only. A
/// direct-mapped torus rather than a fixed window, so a contour that
/// wanders or grows far from its starting circle is still served (two
/// pixels share a slot only 64 apart in both axes at once). Values are
/// exactly those of [`box_sum`] and of the central difference of its
/// means, so the contour moves exactly as with direct reads.
struct BoxSums<'a, 'b> {
    img: &'a ImageView<'b>,
    /// `tag << 16 | sum` (a sum is at most 6375).
    sums: [u32; CACHE_SIDE * CACHE_SIDE],
    gtags: [u16; CACHE_SIDE * CACHE_SIDE],
    grads: [f32; CACHE_SIDE * CACHE_SIDE],
}

impl<'a, 'b> BoxSums<'a, 'b> {
    /// An empty cache over `img`.
    fn new(img: &'a ImageView<'b>) -> Self {
        BoxSums {
            img,
            sums: [u32::MAX; CACHE_SIDE * CACHE_SIDE],
            gtags: [UNSET; CACHE_SIDE * CACHE_SIDE],
            grads: [0.0; CACHE_SIDE * CACHE_SIDE],
        }
    }

    /// Slot and tag of pixel `(x, y)`; `None` outside the memo's range.
    fn key(x: i32, y: i32) -> Option<(usize, u16)> {
        // x + 1, y + 1: the snake reads x, y ≥ −1
        let (kx, ky) = (x.wrapping_add(1) as u32, y.wrapping_add(1) as u32);
        if kx >= TAG_LIMIT || ky >= TAG_LIMIT {
            return None;
        }
        let side = CACHE_SIDE as u32;
        let slot = ((ky % side) * side + kx % side) as usize;
        Some((slot, (((ky / side) << 8) | (kx / side)) as u16))
    }

    fn sum(&mut self, x: i32, y: i32) -> u32 {
        if let Some((slot, tag)) = Self::key(x, y) {
            if let Some(e) = self.sums.get_mut(slot) {
                if (*e >> 16) as u16 != tag {
                    *e = ((tag as u32) << 16) | box_sum(self.img, x, y);
                }
                return *e & 0xFFFF;
            }
        }
        box_sum(self.img, x, y)
    }

    /// 5 × 5 box mean at `(x, y)` (replicated border).
    fn smooth(&mut self, x: i32, y: i32) -> f32 {
        self.sum(x, y) as f32 / 25.0
    }

    /// Central-difference gradient magnitude of the box mean.
    fn grad(&mut self, x: i32, y: i32) -> f32 {
        let Some((slot, tag)) = Self::key(x, y) else {
            return self.grad_direct(x, y);
        };
        if self.gtags.get(slot) == Some(&tag) {
            if let Some(&g) = self.grads.get(slot) {
                return g;
            }
        }
        let g = self.grad_direct(x, y);
        if let (Some(t), Some(v)) = (self.gtags.get_mut(slot), self.grads.get_mut(slot)) {
            *t = tag;
            *v = g;
        }
        g
    }

    /// [`BoxSums::grad`] from the memoised sums.
    fn grad_direct(&mut self, x: i32, y: i32) -> f32 {
        let gx = self.smooth(x + 1, y) - self.smooth(x - 1, y);
        let gy = self.smooth(x, y + 1) - self.smooth(x, y - 1);
        libm::sqrtf(gx * gx + gy * gy)
    }
}

/// Background level around `bbox`: median and 1.4826·MAD of up to 512 pixels
/// on the border of `bbox` grown by `margin` (clipped to the image).
pub fn background_level(img: &ImageView<'_>, bbox: Roi, margin: u32) -> (f32, f32) {
    let r = bbox.expand_clipped(margin, img.width() as u32, img.height() as u32);
    let mut buf = [0u8; RING_SAMPLES];
    if r.is_empty() {
        return (0.0, 0.0);
    }
    let per = 2 * (r.w as u64 + r.h as u64);
    let step = per.div_ceil(RING_SAMPLES as u64).max(1);
    let mut n = 0usize;
    let mut k = 0u64;
    while k < per && n < RING_SAMPLES {
        let (x, y) = if k < r.w as u64 {
            (r.x as u64 + k, r.y as u64)
        } else if k < 2 * r.w as u64 {
            (r.x as u64 + k - r.w as u64, r.bottom() as u64 - 1)
        } else if k < 2 * r.w as u64 + r.h as u64 {
            (r.x as u64, r.y as u64 + k - 2 * r.w as u64)
        } else {
            (
                r.right() as u64 - 1,
                r.y as u64 + k - 2 * r.w as u64 - r.h as u64,
            )
        };
        if let Some(v) = img.get(x as usize, y as usize) {
            if let Some(b) = buf.get_mut(n) {
                *b = v;
                n += 1;
            }
        }
        k += step;
    }
    let s = buf.get_mut(..n).unwrap_or(&mut []);
    if s.is_empty() {
        return (0.0, 0.0);
    }
    s.sort_unstable();
    let med = s.get(n / 2).copied().unwrap_or(0);
    let mut dev = [0u8; RING_SAMPLES];
    for (d, v) in dev.iter_mut().zip(s.iter()) {
        *d = v.abs_diff(med);
    }
    let dv = dev.get_mut(..n).unwrap_or(&mut []);
    dv.sort_unstable();
    let mad = dv.get(n / 2).copied().unwrap_or(0);
    (med as f32, 1.4826 * mad as f32)
}

/// Mean grey level of the `side × side` square just beyond `end` along the
/// unit direction `dir` (its centre `side/2 + 1` pixels out): the cheap test
/// of whether anything brighter than the background continues past an end.
/// `None` when less than half the square lies inside the image.
pub fn end_probe(img: &ImageView<'_>, end: (f32, f32), dir: (f32, f32), side: u32) -> Option<f32> {
    let side = side.clamp(1, 256) as i64;
    let off = side as f32 * 0.5 + 1.0;
    let (cx, cy) = (end.0 + dir.0 * off, end.1 + dir.1 * off);
    if !(cx.is_finite() && cy.is_finite() && cx.abs() < 1.0e7 && cy.abs() < 1.0e7) {
        return None;
    }
    let x0 = micromath::F32(cx).round().0 as i64 - side / 2;
    let y0 = micromath::F32(cy).round().0 as i64 - side / 2;
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (xa, xb) = (x0.max(0), (x0 + side).min(w));
    let (ya, yb) = (y0.max(0), (y0 + side).min(h));
    if xb <= xa || yb <= ya || 2 * (xb - xa) * (yb - ya) < side * side {
        return None;
    }
    let mut sum = 0u64;
    for y in ya..yb {
        let row = img.row(y as usize);
        for &v in row.get(xa as usize..xb as usize)? {
            sum += v as u64;
        }
    }
    Some(sum as f32 / ((xb - xa) * (yb - ya)) as f32)
}

/// Runs the tail snake beside the end point `end` of an object whose
/// outward axis direction is `dir` (unit vector), oriented-box height `h_o`,
/// body mean grey level `body_mean`, background `(bg, bg_sd)`, and `fin`
/// the contrast above the background measured just beyond the end
/// ([`end_probe`]; `≤ 0`: unknown).
#[allow(clippy::too_many_arguments)]
pub fn tail_snake(
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
    let mut sums = BoxSums::new(img);
    let limit = p.iterations.min(1000);
    let mut sweeps = 0;
    // hashes of the contours after the last HISTORY sweeps (`hashes[n %
    // HISTORY]` after sweep n; sweep 0 is the starting circle)
    let mut hashes = [0u64; HISTORY];
    if let Some(h0) = hashes.first_mut() {
        *h0 = contour_hash(&pts);
    }
    // a cycle under test: (sweep, period, contour after that sweep)
    let mut pending: Option<(usize, usize, Contour)> = None;
    // once a cycle is confirmed: the sweep whose contour is the last one's
    let mut stop_at: Option<usize> = None;
    for _ in 0..limit {
        if stop_at == Some(sweeps as usize) {
            sweeps = limit;
            break;
        }
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
                    let g = sums.grad(qx, qy);
                    gmax = gmax.max(g);
                    let inside = if sums.smooth(qx, qy) >= level {
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
        // A sweep is a function of the contour alone (the image, end and
        // level are fixed), so once the contour repeats the one of `per`
        // sweeps ago it cycles with period `per` for good. Cycles are found
        // by hash and confirmed on the contour: when the contour after
        // sweep n0 recurs after sweep n0 + per, the last sweep's contour is
        // the one (limit − n) mod per sweeps after this one, and the rest
        // need not run.
        let n = sweeps as usize;
        if stop_at.is_none() {
            let hc = contour_hash(&pts);
            if let Some((n0, per, c)) = pending {
                if n == n0 + per {
                    pending = None;
                    if c == pts {
                        stop_at = Some(n + (limit as usize - n) % per);
                        #[cfg(test)]
                        if per > 8 {
                            LONG_CYCLES.with(|k| k.set(k.get() + 1));
                        }
                    }
                }
            }
            if pending.is_none() && stop_at.is_none() {
                for per in 2..HISTORY.min(n + 1) {
                    if hashes.get((n - per) % HISTORY) == Some(&hc) {
                        pending = Some((n, per, pts));
                        break;
                    }
                }
            }
            if let Some(hn) = hashes.get_mut(n % HISTORY) {
                *hn = hc;
            }
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
    let (n_in, n_hi, far, near) = fill_polygon(img, &pts, (xa, ya, xb, yb), level, end, (ux, uy));
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

/// The x-coordinates where the polygon's edges cross the row `y`, as the
/// even–odd point-in-polygon test computes them (edge `j → i` crosses when
/// `(yᵢ > y) != (yⱼ > y)`, at `xⱼ + (y − yⱼ)(xᵢ − xⱼ)/(yᵢ − yⱼ)`), sorted
/// ascending: a pixel `x` of the row is inside when an odd number of them
/// exceed it.
fn row_crossings(pts: &[(f32, f32); SNAKE_POINTS], y: f32, out: &mut [f32; SNAKE_POINTS]) -> usize {
    let mut n = 0;
    let mut j = SNAKE_POINTS - 1;
    for i in 0..SNAKE_POINTS {
        let (xi, yi) = pts[i];
        let (xj, yj) = pts[j];
        if (yi > y) != (yj > y) {
            let xc = xj + (y - yj) * (xi - xj) / (yi - yj);
            // `x < NaN` never toggles the test: a NaN crossing is no crossing
            if !xc.is_nan() {
                if let Some(o) = out.get_mut(n) {
                    *o = xc;
                    n += 1;
                }
            }
        }
        j = i;
    }
    // ascending (no NaN here; ±0 in either order count alike below)
    out.get_mut(..n)
        .unwrap_or(&mut [])
        .sort_unstable_by(f32::total_cmp);
    n
}

/// Scan-converts the contour over the pixel box `(xa, ya, xb, yb)`: pixels
/// inside it by the even–odd rule (`n_in`), those of them whose 5 × 5 box
/// mean (replicated border) is at or above `level` (`n_hi`), and the far
/// and near extents of the latter along `u` from `end`.
///
/// Exactly the per-pixel even–odd test (`naive::point_in_polygon`) with [`box_sum`]
/// reads (the crossings of a row are the test's own, so parity agrees
/// pixel by pixel; the box sum is separable under the replicated border),
/// but each row's crossings are found once and the box sums slide along
/// the row: about 5 pixel reads per pixel of the box instead of 25 reads
/// and a 32-edge test per inside pixel.
fn fill_polygon(
    img: &ImageView<'_>,
    pts: &[(f32, f32); SNAKE_POINTS],
    (xa, ya, xb, yb): (i32, i32, i32, i32),
    level: f32,
    end: (f32, f32),
    (ux, uy): (f32, f32),
) -> (u32, u32, f32, f32) {
    let (mut n_in, mut n_hi) = (0u32, 0u32);
    let mut far = f32::NEG_INFINITY;
    let mut near = f32::INFINITY;
    let (w, h) = (img.width() as i64, img.height() as i64);
    if w == 0 || h == 0 || xb < xa {
        return (0, 0, far, near);
    }
    let mut xs = [0.0f32; SNAKE_POINTS];
    for y in ya..=yb {
        let n = row_crossings(pts, y as f32, &mut xs);
        if n == 0 {
            continue;
        }
        let xs = xs.get(..n).unwrap_or(&[]);
        // the five rows of the box, replicated at the image's edges
        let rows: [&[u8]; 5] =
            core::array::from_fn(|k| img.row((y as i64 + k as i64 - 2).clamp(0, h - 1) as usize));
        let col = |x: i64| -> u32 {
            let xc = x.clamp(0, w - 1) as usize;
            rows.iter()
                .map(|r| r.get(xc).copied().unwrap_or(0) as u32)
                .sum()
        };
        let x0 = xa as i64;
        // the window of column sums at x − 2 ..= x + 2 for x = xa
        let mut ring = [0u32; 5];
        for (k, c) in ring.iter_mut().enumerate() {
            *c = col(x0 + k as i64 - 2);
        }
        let mut sum: u32 = ring.iter().sum();
        // crossings at or left of x (the rest, n − k, exceed x)
        let mut k = 0usize;
        for x in xa..=xb {
            let xf = x as f32;
            while k < n && xs.get(k).is_some_and(|&c| c <= xf) {
                k += 1;
            }
            if (n - k) % 2 == 1 {
                n_in += 1;
                if sum as f32 / 25.0 >= level {
                    n_hi += 1;
                    let t = (xf - end.0) * ux + (y as f32 - end.1) * uy;
                    far = far.max(t);
                    near = near.min(t);
                }
            }
            // slide the window one column right
            let slot = (x - xa) as usize % 5;
            let add = col(x as i64 + 3);
            if let Some(c) = ring.get_mut(slot) {
                sum = sum - *c + add;
                *c = add;
            }
        }
    }
    (n_in, n_hi, far, near)
}

#[cfg(test)]
#[path = "snake_naive.rs"]
mod naive;

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A `w × h` scene: noisy background, a bright body ending at column
    /// `body_end` and a dimmer fin beyond it, of random extents.
    fn random_scene(
        w: usize,
        h: usize,
        seed: u64,
        body_end: usize,
        fin: (usize, usize, u8),
    ) -> Vec<u8> {
        let mut state = seed | 1;
        let mut px = vec![0u8; w * h];
        let cy = h / 2;
        for y in 0..h {
            for x in 0..w {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let noise = (state % 9) as u8;
                let mut v = 20 + noise;
                if x < body_end && y.abs_diff(cy) < h / 5 {
                    v = 120 + noise;
                } else if x >= body_end && x < body_end + fin.0 && y.abs_diff(cy) < fin.1 {
                    v = 20u8.saturating_add(fin.2) + noise;
                }
                px[y * w + x] = v;
            }
        }
        px
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 2 } else { 48 }))]
        /// The memoised box sums and the cycle shortcut leave every output
        /// (contour, sweeps, area, acceptance) exactly as the direct snake.
        /// (Not under Miri: scenes up to 200² px and 260 sweeps take more
        /// than 20 minutes there; `long_cycles_end_as_the_direct_snake`
        /// runs the same two snakes on small scenes under Miri.)
        #[test]
        #[cfg_attr(miri, ignore)]
        fn matches_the_direct_snake(
            w in 40usize..200, h in 40usize..200, seed in any::<u64>(),
            body_frac in 0.2f32..0.9, fin_len in 0usize..80, fin_half in 1usize..60,
            fin_c in 0u8..60, h_o in 4.0f32..300.0, iterations in 1u16..260,
            fin_probe in 0.0f32..40.0, ey in -5.0f32..5.0, flip in any::<bool>(),
        ) {
            let body_end = ((w as f32 * body_frac) as usize).max(1);
            let px = random_scene(w, h, seed, body_end, (fin_len, fin_half, fin_c));
            let img = ImageView::packed(&px, w, h).unwrap();
            let p = SnakeParams { iterations, ..SnakeParams::default() };
            let (end, dir) = if flip {
                ((body_end as f32 - 0.5, h as f32 / 2.0 + ey), (1.0, 0.0))
            } else {
                ((body_end as f32 - 0.5, h as f32 / 2.0 + ey), (-0.6, 0.8))
            };
            let bg = background_level(&img, Roi { x: 0, y: 0, w: body_end as u32, h: h as u32 }, 4);
            let fast = tail_snake(&img, end, dir, h_o, 124.0, bg, fin_probe, &p);
            let slow = naive::tail_snake_naive(&img, end, dir, h_o, 124.0, bg, fin_probe, &p);
            prop_assert_eq!(fast, slow);
        }

        /// The scan conversion counts exactly the pixels the per-pixel
        /// even–odd test and direct box sums find, for any contour: star
        /// shaped or self-intersecting, partly or wholly off the image.
        #[test]
        fn fill_polygon_equals_the_per_pixel_test(
            w in 1usize..90, h in 1usize..90, seed in any::<u64>(),
            pts in proptest::collection::vec((-30.0f32..120.0, -30.0f32..120.0), SNAKE_POINTS),
            whole in any::<bool>(), level in 0.0f32..40.0,
            end in (-10.0f32..100.0, -10.0f32..100.0), ang in 0.0f32..6.3,
        ) {
            let px = random_scene(w, h, seed, w / 2, (w / 4, h / 4 + 1, 10));
            let img = ImageView::packed(&px, w, h).unwrap();
            let mut poly = [(0.0f32, 0.0f32); SNAKE_POINTS];
            for (q, p) in poly.iter_mut().zip(pts.iter()) {
                // whole pixels, as the snake's contours are, or fractional
                *q = if whole { (p.0.round(), p.1.round()) } else { *p };
            }
            let u = (libm::cosf(ang), libm::sinf(ang));
            let (x0, x1) = poly.iter().fold((f32::MAX, f32::MIN), |a, q| (a.0.min(q.0), a.1.max(q.0)));
            let (y0, y1) = poly.iter().fold((f32::MAX, f32::MIN), |a, q| (a.0.min(q.1), a.1.max(q.1)));
            let bx = (
                x0.max(0.0) as i32,
                y0.max(0.0) as i32,
                x1.min(w as f32 - 1.0) as i32,
                y1.min(h as f32 - 1.0) as i32,
            );
            let fast = fill_polygon(&img, &poly, bx, level, end, u);
            let (mut n_in, mut n_hi, mut far, mut near) = (0u32, 0u32, f32::NEG_INFINITY, f32::INFINITY);
            for y in bx.1..=bx.3 {
                for x in bx.0..=bx.2 {
                    if !naive::point_in_polygon(&poly, x as f32, y as f32) {
                        continue;
                    }
                    n_in += 1;
                    if box_sum(&img, x, y) as f32 / 25.0 >= level {
                        n_hi += 1;
                        let t = (x as f32 - end.0) * u.0 + (y as f32 - end.1) * u.1;
                        far = far.max(t);
                        near = near.min(t);
                    }
                }
            }
            prop_assert_eq!(fast, (n_in, n_hi, far, near));
        }
    }

    /// Scenes drawn as in `matches_the_direct_snake`, 300 of them: the
    /// contour equals the direct snake's on every one, and the long-cycle
    /// shortcut (hash found, confirmed, the remainder run) is among the
    /// paths taken.
    #[test]
    fn long_cycles_end_as_the_direct_snake() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |m: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % m
        };
        LONG_CYCLES.with(|k| k.set(0));
        let scenes = if cfg!(miri) { 2 } else { 300 };
        for _ in 0..scenes {
            // Miri: two small scenes of few sweeps (the path, not the figure)
            let side = if cfg!(miri) { 8 } else { 160 };
            let (w, h) = (40 + next(side) as usize, 40 + next(side) as usize);
            let body_end = ((w as u64 * (20 + next(70)) / 100) as usize).max(1);
            let fin = (next(80) as usize, 1 + next(59) as usize, next(60) as u8);
            let px = random_scene(w, h, next(u64::MAX), body_end, fin);
            let img = ImageView::packed(&px, w, h).unwrap();
            let iterations = if cfg!(miri) {
                12
            } else {
                200 + next(60) as u16
            };
            let p = SnakeParams {
                iterations,
                ..SnakeParams::default()
            };
            let h_o = 4.0 + next(296) as f32;
            let end = (body_end as f32 - 0.5, h as f32 / 2.0);
            let dir = if next(2) == 0 {
                (1.0, 0.0)
            } else {
                (-0.6, 0.8)
            };
            let bg = background_level(
                &img,
                Roi {
                    x: 0,
                    y: 0,
                    w: body_end as u32,
                    h: h as u32,
                },
                4,
            );
            let fin_probe = next(40) as f32;
            let fast = tail_snake(&img, end, dir, h_o, 124.0, bg, fin_probe, &p);
            let slow = naive::tail_snake_naive(&img, end, dir, h_o, 124.0, bg, fin_probe, &p);
            assert_eq!(fast, slow);
        }
        let long = LONG_CYCLES.with(|k| k.get());
        assert!(
            cfg!(miri) || long > 0,
            "no scene took the long-cycle shortcut"
        );
    }

    /// Background 20, a "fin" of grey 30 over x ∈ [60, 80), y ∈ [40, 60)
    /// (`wide`: x ∈ [60, 90), y ∈ [30, 70)).
    fn scene(wide: bool) -> [u8; 100 * 100] {
        let mut px = [20u8; 100 * 100];
        let (ys, xs) = if wide {
            (30..70, 60..90)
        } else {
            (40..60, 60..80)
        };
        for y in ys {
            for x in xs.clone() {
                px[y * 100 + x] = 30;
            }
        }
        px
    }

    #[test]
    fn end_probe_reads_the_square_beyond_the_end() {
        let px = scene(false);
        let img = ImageView::packed(&px, 100, 100).unwrap();
        // end at x = 59, looking +x: square of side 10 centred at x = 65 → all fin
        let m = end_probe(&img, (59.0, 50.0), (1.0, 0.0), 10).unwrap();
        assert_eq!(m, 30.0);
        // looking −x from x = 59: background only
        let m = end_probe(&img, (59.0, 50.0), (-1.0, 0.0), 10).unwrap();
        assert_eq!(m, 20.0);
        // centred at x = 80 (end at 74): half fin (x 75..80), half water (80..85)
        let m = end_probe(&img, (74.0, 50.0), (1.0, 0.0), 10).unwrap();
        assert_eq!(m, 25.0);
        // mostly outside the image
        assert_eq!(end_probe(&img, (98.0, 50.0), (1.0, 0.0), 10), None);
        assert_eq!(end_probe(&img, (f32::NAN, 50.0), (1.0, 0.0), 10), None);
    }

    #[test]
    fn the_fin_level_lets_the_snake_cover_a_dim_fin() {
        let px = scene(true);
        let img = ImageView::packed(&px, 100, 100).unwrap();
        let p = SnakeParams::default();
        // body 20 + 100 = 120: the body-relative level (20 + 15) is above the
        // fin, the fin-relative one (20 + 5) below it
        let run = |fin: f32| {
            tail_snake(
                &img,
                (59.5, 50.0),
                (1.0, 0.0),
                40.0,
                120.0,
                (20.0, 0.0),
                fin,
                &p,
            )
        };
        let blind = run(0.0);
        assert!(!blind.accepted);
        let seen = run(10.0);
        assert_eq!(seen.level, 25.0);
        assert!(seen.accepted, "{seen:?}");
        // the region stops at the fin's edge (x = 89, 29.5 px beyond the end)
        assert!((seen.far_t - 29.5).abs() <= 2.0, "{}", seen.far_t);
    }
}
