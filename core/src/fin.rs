//! Dim caudal fin by its intensity profile (Section IV.D.1's tail
//! compensation, beyond the snake).
//!
//! A dim fin (a few grey levels above the water) lost alike in both views
//! costs 12–17 % of a fish's length and no stereo check sees it. The tail
//! snake ([`crate::snake`]) decides pixel by pixel against a level that
//! must stand above the pixel noise, so a fin 1–2 grey levels above the
//! water (noise σ ≈ 1.2) is invisible to it. Averaged across the fin, the
//! same fin stands out: the mean of `2J + 1` pixels on the perpendicular
//! through a point of the axis has noise `σ/√(2J + 1)`.
//!
//! - Profile: for `k = 1, 2, …, K` pixels beyond the end along the outward
//!   axis, the mean grey level of the segment of half-length `J = h_o/3`
//!   perpendicular to the axis (nearest pixels) minus the mean of the two
//!   side segments `2J + 2 ≤ |j| ≤ 3J + 2` (the water beside the fin: a
//!   local background, whatever the light's gradient). In the right view
//!   the same points are shifted by the disparity line at their axis
//!   position.
//! - The fin is there when both views' profiles start (mean of `k = 1…4`)
//!   at least the level `noise_k` times the noise of a 5-sample mean of the
//!   profile above the water, and at most half the body's contrast (a fin
//!   is dimmer than the body; brighter is a neighbour or glow).
//! - Its reach in one view: the first `k` where the profile's 5-sample
//!   mean falls below that level.
//!   The two views' reaches must agree (within 30 % or 4 px); the end moves
//!   out by the smaller one, at most `max_fraction` of the body's length.
//!
//! - Only at the tail: the end whose last tenth of the mask holds fewer
//!   pixels than the other's ([`end_slabs`]; a fish tapers to its tail
//!   and is blunt at its head — something dim beyond the head is glow or a
//!   neighbour, not a fin).
//!
//! Bounded work: `K ≤ 1024` samples of `2J + 1 ≤ 513` pixels per view;
//! memory: the profile (`K` floats, 4 KiB) on the stack. No heap, no panic.

use crate::image::ImageView;
use crate::object::Run;

/// Mask pixels within `frac` of the length of each end along the axis
/// (`t ≤ t_lo + frac·(t_hi − t_lo)` and `t ≥ t_hi − frac·(t_hi − t_lo)`):
/// a fish tapers to its tail (the caudal peduncle, whose fin may be lost)
/// and is blunt at its head, so the tail is the end with the smaller slab.
pub fn end_slabs(
    runs: &[Run],
    centre: (f32, f32),
    dir: (f32, f32),
    t: (f32, f32),
    frac: f32,
) -> (u32, u32) {
    let span = t.1 - t.0;
    let (lo, hi) = (t.0 + frac * span, t.1 - frac * span);
    let (mut a, mut b) = (0u32, 0u32);
    for r in runs {
        let yy = (r.y as f32 - centre.1) * dir.1;
        for x in r.x0..r.x1 {
            let tt = (x as f32 - centre.0) * dir.0 + yy;
            if tt <= lo {
                a = a.saturating_add(1);
            }
            if tt >= hi {
                b = b.saturating_add(1);
            }
        }
    }
    (a, b)
}

/// Longest profile, pixels.
pub const MAX_PROFILE: usize = 1024;

/// Where the profile is taken and how it is read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinProbe {
    /// End point (left view) the profile starts from.
    pub end: (f32, f32),
    /// Outward unit direction of the axis at the end.
    pub dir: (f32, f32),
    /// Half-length `J` of the perpendicular segments.
    pub half: u32,
    /// Profile length `K`, pixels.
    pub len: u32,
}

/// Mean of the perpendicular segment `j ∈ [j0, j1]` through `end + k·dir`
/// shifted left by `shift` (the right view's disparity there); `None` when
/// fewer than half its pixels are inside the image.
fn segment_mean(
    img: &ImageView<'_>,
    p: &FinProbe,
    k: f32,
    shift: f32,
    j0: i32,
    j1: i32,
) -> Option<f32> {
    let (nx, ny) = (-p.dir.1, p.dir.0);
    let (cx, cy) = (p.end.0 + k * p.dir.0 - shift, p.end.1 + k * p.dir.1);
    let (w, h) = (img.width() as f32, img.height() as f32);
    let (mut sum, mut n) = (0u32, 0u32);
    for j in j0..=j1 {
        let x = libm::roundf(cx + j as f32 * nx);
        let y = libm::roundf(cy + j as f32 * ny);
        if !(x >= 0.0 && y >= 0.0 && x < w && y < h) {
            continue;
        }
        if let Some(v) = img.get(x as usize, y as usize) {
            sum += v as u32;
            n += 1;
        }
    }
    if n == 0 || 2 * n < (j1 - j0 + 1).max(0) as u32 {
        return None;
    }
    Some(sum as f32 / n as f32)
}

/// Contrast of the central segment `|j| ≤ J` over the two side segments
/// `J_out ≤ |j| ≤ J_out + J` at `k` pixels out: the fin against the water
/// beside it (a local background, whatever the light's gradient).
fn contrast_at(img: &ImageView<'_>, p: &FinProbe, k: f32, shift: f32, out: i32) -> Option<f32> {
    let half = p.half.min(256) as i32;
    let c = segment_mean(img, p, k, shift, -half, half)?;
    let a = segment_mean(img, p, k, shift, out, out + half)?;
    let b = segment_mean(img, p, k, shift, -out - half, -out)?;
    Some(c - 0.5 * (a + b))
}

/// The fin's reach in one view (see the module documentation): `None`
/// when no fin starts at the end. `disparity(k)` gives the shift of the
/// sample `k` pixels out (0 in the left view); `noise` is the view's pixel
/// noise σ, `body_contrast` the body's mean over the background.
pub fn fin_reach(
    img: &ImageView<'_>,
    p: &FinProbe,
    disparity: impl Fn(f32) -> f32,
    noise: f32,
    body_contrast: f32,
    noise_k: f32,
) -> Option<f32> {
    let len = (p.len as usize).clamp(1, MAX_PROFILE);
    let half = p.half.min(256) as i32;
    // the side segments clear a fan as tall as the body (h_o ≈ 3J)
    let out = (2 * half + 2).max(half + 2);
    let mut prof = [0.0f32; MAX_PROFILE];
    // the profile is taken lazily (a whole tail or a head stops it after a
    // few samples); `valid` samples taken, `open` while more may follow
    let mut valid = 0usize;
    let mut open = true;
    let take = |upto: usize, prof: &mut [f32; MAX_PROFILE], valid: &mut usize, open: &mut bool| {
        while *open && *valid < upto.min(len) {
            let kk = (*valid + 1) as f32;
            match (
                contrast_at(img, p, kk, disparity(kk), out),
                prof.get_mut(*valid),
            ) {
                (Some(v), Some(slot)) => {
                    *slot = v;
                    *valid += 1;
                }
                _ => *open = false,
            }
        }
        if *valid >= len {
            *open = false;
        }
    };
    take(8, &mut prof, &mut valid, &mut open);
    if valid < 8 {
        return None;
    }
    // noise of a 5-sample mean of (centre − mean of the sides)
    let nc = (2 * half + 1) as f32;
    let level =
        noise_k * noise * libm::sqrtf(1.0 / nc + 0.5 / (half + 1) as f32) / libm::sqrtf(5.0);
    let start = prof.get(..4)?.iter().sum::<f32>() / 4.0;
    if !(start >= level && start <= 0.5 * body_contrast) {
        return None;
    }
    let mut k = 0usize;
    while k < valid {
        take(k + 3, &mut prof, &mut valid, &mut open);
        let win = prof.get(k.saturating_sub(2)..(k + 3).min(valid))?;
        if win.iter().sum::<f32>() / (win.len() as f32) < level {
            return Some(k as f32);
        }
        k += 1;
    }
    Some(valid as f32)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    extern crate std;
    use std::vec::Vec;

    /// Water at 40 with a left-to-right light gradient and ±2 noise; a body
    /// (x < 200, contrast 50) and beyond it along +x a fin `fin` grey levels
    /// above the water from x = 200 to 200 + `reach`, 40 px tall.
    fn image(fin: f32, reach: usize) -> Vec<u8> {
        let (w, h) = (512usize, 160usize);
        let mut img = std::vec![0u8; w * h];
        let mut state = 12345u32;
        for y in 0..h {
            for x in 0..w {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let noise = ((state >> 24) % 5) as f32 - 2.0;
                let mut v = 40.0 + x as f32 * 0.02 + noise;
                let dy = (y as i32 - 80).abs();
                if x < 200 && dy <= 24 {
                    v += 50.0;
                } else if x >= 200 && x < 200 + reach && dy <= 20 {
                    v += fin;
                }
                img[y * w + x] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    fn probe() -> FinProbe {
        FinProbe {
            end: (199.5, 80.0),
            dir: (1.0, 0.0),
            half: 16,
            len: 120,
        }
    }

    #[test]
    fn a_fin_two_grey_levels_above_the_water_is_found_to_its_edge() {
        let img = image(2.0, 60);
        let v = ImageView::packed(&img, 512, 160).unwrap();
        let r = fin_reach(&v, &probe(), |_| 0.0, 1.4, 50.0, 4.0).unwrap();
        assert!((r - 60.0).abs() <= 4.0, "reach {r}");
    }

    #[test]
    fn water_beyond_the_end_is_no_fin() {
        let img = image(0.0, 0);
        let v = ImageView::packed(&img, 512, 160).unwrap();
        assert_eq!(fin_reach(&v, &probe(), |_| 0.0, 1.4, 50.0, 4.0), None);
    }

    #[test]
    fn something_as_bright_as_the_body_is_no_fin() {
        let img = image(45.0, 60);
        let v = ImageView::packed(&img, 512, 160).unwrap();
        assert_eq!(fin_reach(&v, &probe(), |_| 0.0, 1.4, 50.0, 4.0), None);
    }

    #[test]
    fn the_right_view_is_read_at_the_shifted_points() {
        // the right view is the left one shifted by 30 px
        let img = image(2.0, 60);
        let mut right = std::vec![40u8; img.len()];
        for y in 0..160 {
            for x in 0..482 {
                right[y * 512 + x] = img[y * 512 + x + 30];
            }
        }
        let v = ImageView::packed(&right, 512, 160).unwrap();
        let r = fin_reach(&v, &probe(), |_| 30.0, 1.4, 50.0, 4.0).unwrap();
        assert!((r - 60.0).abs() <= 4.0, "reach {r}");
        // read without the shift, the profile starts on the body's edge
        // beyond the (shifted) fin: no fin where the left view has one
        let r0 = fin_reach(&v, &probe(), |_| 0.0, 1.4, 50.0, 4.0);
        assert!(r0.is_none_or(|r| (r - 60.0).abs() > 4.0), "{r0:?}");
    }

    #[test]
    fn out_of_the_image_is_none_not_a_panic() {
        let img = image(2.0, 60);
        let v = ImageView::packed(&img, 512, 160).unwrap();
        let mut p = probe();
        p.end = (1.0e9, f32::NAN);
        assert_eq!(fin_reach(&v, &p, |_| 0.0, 1.4, 50.0, 4.0), None);
        p = probe();
        p.half = u32::MAX;
        p.len = u32::MAX;
        let _ = fin_reach(&v, &p, |_| f32::INFINITY, f32::NAN, 50.0, 4.0);
    }

    #[test]
    fn the_tapered_end_has_the_smaller_slab() {
        // a wedge: 41 rows tall at x = 0, 1 row at x = 100
        let mut runs = Vec::new();
        for y in 0..41u16 {
            let half = (y as i32 - 20).unsigned_abs() as u16;
            runs.push(Run {
                y,
                x0: 0,
                x1: 100 - 5 * half.min(20),
            });
        }
        let (blunt, taper) = end_slabs(&runs, (50.0, 20.0), (1.0, 0.0), (-50.0, 50.0), 0.1);
        assert!(taper < blunt, "{blunt} {taper}");
        // seen the other way round, the other end
        let (taper2, blunt2) = end_slabs(&runs, (50.0, 20.0), (-1.0, 0.0), (-50.0, 50.0), 0.1);
        assert_eq!((taper2, blunt2), (taper, blunt));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Random images and probes: never a panic; a reach lies within the
        /// profile; the end slabs never count more pixels than the mask.
        #[test]
        fn reach_and_slabs_never_panic(
            seed in 0u32..1000,
            w in 1usize..64,
            h in 1usize..32,
            p in (-10.0f32..80.0, -10.0f32..40.0, -1.0f32..1.0, 0u32..40, 0u32..200),
            shift in -20.0f32..20.0,
            noise in 0.0f32..5.0,
            runs in proptest::collection::vec((0u16..40, 0u16..80, 0u16..20), 0..20),
        ) {
            let mut st = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
            let img: Vec<u8> = (0..w * h).map(|_| { st = st.wrapping_mul(1_664_525).wrapping_add(1_013_904_223); (st >> 24) as u8 }).collect();
            let v = ImageView::packed(&img, w, h).unwrap();
            let a = p.2 * 3.2;
            let probe = FinProbe { end: (p.0, p.1), dir: (libm::cosf(a), libm::sinf(a)), half: p.3, len: p.4 };
            if let Some(r) = fin_reach(&v, &probe, |k| shift * k / 10.0, noise, 60.0, 4.0) {
                proptest::prop_assert!(r >= 0.0 && r <= p.4.clamp(1, MAX_PROFILE as u32) as f32);
            }
            let rs: Vec<Run> = runs.iter().map(|&(y, x0, n)| Run { y, x0, x1: x0.saturating_add(n) }).collect();
            let area: u32 = rs.iter().map(|r| r.len()).sum();
            let (s0, s1) = end_slabs(&rs, (20.0, 10.0), (libm::cosf(a), libm::sinf(a)), (-30.0, 30.0), 0.1);
            proptest::prop_assert!(s0 <= area && s1 <= area);
        }
    }
}
