//! Writing a synthetic haul in the input layout of DESIGN.md
//! (`left/NNNNNN.png`, `right/NNNNNN.png`, `calibration.yml`) plus
//! `truth.json` ([`crate::truth`] schema). Every file is written to a
//! temporary name in its folder and renamed, so an interrupted run never
//! leaves a file that looks complete but is not.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Context;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use nalgebra::Vector3;
use rayon::prelude::*;

use crate::truth::{Truth, TruthFish, TruthFrame, TRUTH_VERSION};

use super::render::{render_view, FishView};
use super::rig::Cam;
use super::{yaml, Haul, SynthConfig, FPS};

/// Writes `bytes` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    std::fs::write(&tmp, bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot rename to {}", path.display()))?;
    Ok(())
}

/// Encodes 8-bit grey pixels as PNG.
pub fn encode_png(width: u32, height: u32, pixels: &[u8]) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub)
        .write_image(pixels, width, height, ExtendedColorType::L8)
        .context("PNG encoding failed")?;
    Ok(out)
}

/// Frame file name: `000001.png`.
pub fn frame_name(frame: u32) -> String {
    format!("{frame:06}.png")
}

/// `v` rounded to `digits` decimals, so `truth.json` holds short numbers
/// that read back exactly (0.1 µm is far below any measurement here).
fn round_to(v: f64, digits: i32) -> f64 {
    let k = 10f64.powi(digits);
    (v * k).round() / k
}

/// The visibility of every fish in every view: `views[frame - 1][cam]`.
pub type Visibility = Vec<[Vec<FishView>; 2]>;

/// Assembles `truth.json` from the plan and what the renderer drew.
pub fn build_truth(haul: &Haul, views: &Visibility) -> Truth {
    let mut per_fish: BTreeMap<usize, Vec<TruthFrame>> = BTreeMap::new();
    for (i, pair) in views.iter().enumerate() {
        let frame = i as u32 + 1;
        let mut both: BTreeMap<usize, [Option<&FishView>; 2]> = BTreeMap::new();
        for cam in Cam::BOTH {
            for v in &pair[cam.index()] {
                both.entry(v.fish).or_default()[cam.index()] = Some(v);
            }
        }
        for (fi, [l, r]) in both {
            let area = |v: Option<&FishView>| v.map_or(0, |v| v.area);
            if area(l) == 0 && area(r) == 0 {
                continue;
            }
            let life = &haul.fish[fi];
            let Some(pose) = life.pose(frame as i64) else {
                continue;
            };
            let (head, tail) = pose.ends(&life.spec);
            let px_left = |p: &Vector3<f64>| {
                haul.rig
                    .project(Cam::Left, p)
                    .map(|(x, y)| [round_to(x + 0.5, 4), round_to(y + 0.5, 4)])
            };
            let mm = |v: f64| round_to(v, 4);
            let bx = |v: Option<&FishView>| {
                v.and_then(|v| v.bbox).map(|[x0, y0, x1, y1]| {
                    [
                        x0 as f64,
                        y0 as f64,
                        (x1 - x0 + 1) as f64,
                        (y1 - y0 + 1) as f64,
                    ]
                })
            };
            let frac = |v: Option<&FishView>| {
                v.map_or(0.0, |v| {
                    if v.full_area == 0 {
                        0.0
                    } else {
                        round_to((v.area as f64 / v.full_area as f64).min(1.0), 6)
                    }
                })
            };
            per_fish.entry(fi).or_default().push(TruthFrame {
                frame,
                left_box: bx(l),
                right_box: bx(r),
                left_area: area(l) as f64,
                right_area: area(r) as f64,
                left_visible_fraction: frac(l),
                right_visible_fraction: frac(r),
                inside_left: l.is_some_and(|v| v.inside),
                inside_right: r.is_some_and(|v| v.inside),
                head_mm: [mm(head.x), mm(head.y), mm(head.z)],
                tail_mm: [mm(tail.x), mm(tail.y), mm(tail.z)],
                // raw left pixels, box convention (pixel centres at +0.5)
                head_px_left: px_left(&head),
                tail_px_left: px_left(&tail),
            });
        }
    }
    let mut order: Vec<(u32, usize)> = per_fish
        .iter()
        .map(|(fi, frames)| (frames[0].frame, *fi))
        .collect();
    order.sort();
    let fish = order
        .into_iter()
        .enumerate()
        .map(|(k, (_, fi))| {
            let spec = &haul.fish[fi].spec;
            TruthFish {
                id: k as u32 + 1,
                length_mm: round_to(spec.length_mm, 6),
                tail_reflectivity: round_to(spec.tail_reflectivity, 6),
                frames: per_fish.remove(&fi).unwrap_or_default(),
            }
        })
        .collect();
    Truth {
        version: TRUTH_VERSION,
        seed: haul.config.seed,
        width: haul.rig.width,
        height: haul.rig.height,
        fps: FPS,
        frames: haul.config.frames,
        fish,
    }
}

/// Renders every view of a planned haul (in parallel); `sink` receives
/// each view's pixels. Returns the visibility table.
pub fn render_all<F>(haul: &Haul, sink: F) -> anyhow::Result<Visibility>
where
    F: Fn(u32, Cam, &[u8]) -> anyhow::Result<()> + Sync,
{
    let jobs: Vec<(u32, Cam)> = (1..=haul.config.frames)
        .flat_map(|f| Cam::BOTH.map(|c| (f, c)))
        .collect();
    let done: Vec<(u32, Cam, Vec<FishView>)> = jobs
        .par_iter()
        .map(|&(frame, cam)| {
            let view = render_view(haul, frame, cam);
            sink(frame, cam, &view.pixels)?;
            Ok((frame, cam, view.fish))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut views: Visibility = (0..haul.config.frames)
        .map(|_| [Vec::new(), Vec::new()])
        .collect();
    for (frame, cam, fish) in done {
        views[(frame - 1) as usize][cam.index()] = fish;
    }
    Ok(views)
}

/// `fishtrack synth`: plans, renders and writes a haul to `dir`; returns its truth.
pub fn write_haul(dir: &Path, config: &SynthConfig) -> anyhow::Result<Truth> {
    let haul = Haul::plan(*config)?;
    for sub in ["left", "right"] {
        std::fs::create_dir_all(dir.join(sub))
            .with_context(|| format!("cannot create {}", dir.join(sub).display()))?;
    }
    let (w, h) = (haul.rig.width, haul.rig.height);
    let bar = crate::progress::bar(2 * u64::from(config.frames), "synth", "views");
    let views = render_all(&haul, |frame, cam, pixels| {
        let sub = match cam {
            Cam::Left => "left",
            Cam::Right => "right",
        };
        let png = encode_png(w, h, pixels)?;
        write_atomic(&dir.join(sub).join(frame_name(frame)), &png)?;
        bar.inc(1);
        Ok(())
    })?;
    bar.finish_and_clear();
    let truth = build_truth(&haul, &views);
    write_atomic(
        &dir.join("calibration.yml"),
        yaml::calibration_yaml(&haul.rig).as_bytes(),
    )?;
    let mut json = serde_json::to_string_pretty(&truth).context("cannot serialise truth")?;
    json.push('\n');
    write_atomic(&dir.join("truth.json"), json.as_bytes())?;
    Ok(truth)
}
