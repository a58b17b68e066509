//! A montage of synthetic stereo frames for the README
//! (`docs/synthetic_montage.png`): one row per frame, left | right,
//! box-downscaled. Regenerate with
//! `cargo test -p fishtrack --release --test synth_tools write_readme_montage -- --ignored`.

use std::path::Path;

use super::output::{encode_png, write_atomic};
use super::render::render_view;
use super::rig::Cam;
use super::{Haul, SynthConfig};

/// Box-downscales a square `size`² image to `thumb`².
fn downscale(src: &[u8], size: usize, thumb: usize) -> Vec<u8> {
    let mut out = vec![0u8; thumb * thumb];
    for ty in 0..thumb {
        let y0 = ty * size / thumb;
        let y1 = ((ty + 1) * size / thumb).max(y0 + 1);
        for tx in 0..thumb {
            let x0 = tx * size / thumb;
            let x1 = ((tx + 1) * size / thumb).max(x0 + 1);
            let mut sum = 0u64;
            for y in y0..y1 {
                for x in x0..x1 {
                    sum += src[y * size + x] as u64;
                }
            }
            out[ty * thumb + tx] = (sum / ((y1 - y0) * (x1 - x0)) as u64) as u8;
        }
    }
    out
}

/// Renders `frames` of the haul `config` and writes the montage to `path`.
pub fn write_montage(
    path: &Path,
    config: SynthConfig,
    frames: &[u32],
    thumb: usize,
) -> anyhow::Result<()> {
    let haul = Haul::plan(config)?;
    let size = config.size as usize;
    let gap = 6;
    let w = 2 * thumb + gap;
    let h = frames.len() * thumb + frames.len().saturating_sub(1) * gap;
    let mut canvas = vec![255u8; w * h];
    for (row, &frame) in frames.iter().enumerate() {
        for cam in Cam::BOTH {
            let view = render_view(&haul, frame, cam);
            let small = downscale(&view.pixels, size, thumb);
            let ox = cam.index() * (thumb + gap);
            let oy = row * (thumb + gap);
            for y in 0..thumb {
                canvas[(oy + y) * w + ox..(oy + y) * w + ox + thumb]
                    .copy_from_slice(&small[y * thumb..(y + 1) * thumb]);
            }
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    write_atomic(path, &encode_png(w as u32, h as u32, &canvas)?)
}
