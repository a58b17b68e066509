//! Float reference of the dim-fin profile (`fishtrack_core::fin`, tail
//! compensation beyond the snake), written for clarity: every segment's
//! pixels collected, then averaged.

use super::stereo::Gray;

/// Longest profile (core: `fin::MAX_PROFILE`).
const MAX_PROFILE: usize = 1024;

/// Mean of the pixels `end + k·dir − (shift, 0) + j·n` for `j ∈ [j0, j1]`
/// (nearest pixels inside the image), at least half of them inside.
#[allow(clippy::too_many_arguments)]
fn segment(
    img: &Gray,
    end: (f64, f64),
    dir: (f64, f64),
    k: f64,
    shift: f64,
    j0: i64,
    j1: i64,
) -> Option<f64> {
    let n = (-dir.1, dir.0);
    let vals: Vec<f64> = (j0..=j1)
        .filter_map(|j| {
            let x = (end.0 + k * dir.0 - shift + j as f64 * n.0).round();
            let y = (end.1 + k * dir.1 + j as f64 * n.1).round();
            l_at(img, x, y)
        })
        .collect();
    if vals.is_empty() || 2 * vals.len() < (j1 - j0 + 1).max(0) as usize {
        return None;
    }
    Some(vals.iter().sum::<f64>() / vals.len() as f64)
}

fn l_at(img: &Gray, x: f64, y: f64) -> Option<f64> {
    if !(x >= 0.0 && y >= 0.0 && x < img.w as f64 && y < img.h as f64) {
        return None;
    }
    img.at(x as i64, y as i64)
}

/// The fin's reach beyond `end` along `dir` in one view (core:
/// `fin::fin_reach`): the first `k` where the 5-sample mean of the centre
/// segment's contrast over the side segments falls below `noise_k` times
/// its noise; `None` when the profile does not start above that level or
/// starts brighter than half the body's contrast.
#[allow(clippy::too_many_arguments)]
pub fn reach(
    img: &Gray,
    end: (f64, f64),
    dir: (f64, f64),
    half: i64,
    len: usize,
    disparity: impl Fn(f64) -> f64,
    noise: f64,
    body_contrast: f64,
    noise_k: f64,
) -> Option<f64> {
    let half = half.min(256);
    let out = 2 * half + 2;
    let mut prof = Vec::new();
    for k in 1..=len.clamp(1, MAX_PROFILE) {
        let (kf, sh) = (k as f64, disparity(k as f64));
        let c = segment(img, end, dir, kf, sh, -half, half);
        let a = segment(img, end, dir, kf, sh, out, out + half);
        let b = segment(img, end, dir, kf, sh, -out - half, -out);
        match (c, a, b) {
            (Some(c), Some(a), Some(b)) => prof.push(c - 0.5 * (a + b)),
            _ => break,
        }
    }
    if prof.len() < 8 {
        return None;
    }
    let nc = (2 * half + 1) as f64;
    let level = noise_k * noise * (1.0 / nc + 0.5 / (half + 1) as f64).sqrt() / 5f64.sqrt();
    let start = prof[..4].iter().sum::<f64>() / 4.0;
    if !(start >= level && start <= 0.5 * body_contrast) {
        return None;
    }
    for k in 0..prof.len() {
        let win = &prof[k.saturating_sub(2)..(k + 3).min(prof.len())];
        if win.iter().sum::<f64>() / (win.len() as f64) < level {
            return Some(k as f64);
        }
    }
    Some(prof.len() as f64)
}
