//! Inputs for the dense-stereo comparison of README ("Stereo pairing and
//! 3-D length"): for frames of a synthetic haul, runs the pipeline, writes
//! the rectified pair (`NNNNNN_left.png`, `NNNNNN_right.png`), the boxes of
//! the left objects that match a truth fish wholly inside both views
//! (`NNNNNN_boxes.json`: rectified box, true length, the core's length) and
//! the geometry (`geometry.txt`: F CX CY CX_RIGHT BASELINE_MM), and prints
//! per frame the core's pairing + length time and SAD operations, re-run on
//! the pipeline's own objects.
//!
//! ```sh
//! cargo run --release -p fishtrack --example dense_inputs -- HAUL OUTDIR 5 10 15
//! python3 scripts/dense_stereo_compare.py OUTDIR/000005_left.png OUTDIR/000005_right.png \
//!     OUTDIR/000005_boxes.json --geometry $(cat OUTDIR/geometry.txt) ...
//! ```

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use fishtrack::track_cmd::{new_pipeline, prepare, raw_box, views, TrackOptions};
use fishtrack::truth::Truth;
use fishtrack_core::length::measure_length;
use fishtrack_core::pipeline::REFINE_BLOCKS;
use fishtrack_core::stereo::pair_objects;

fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let ix = (a[0] + a[2]).min(b[0] + b[2]) - a[0].max(b[0]);
    let iy = (a[1] + a[3]).min(b[1] + b[3]) - a[1].max(b[1]);
    let i = ix.max(0.0) * iy.max(0.0);
    let u = a[2] * a[3] + b[2] * b[3] - i;
    if u > 0.0 {
        i / u
    } else {
        0.0
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        anyhow::bail!("usage: dense_inputs HAUL OUTDIR FRAME...");
    }
    let haul = PathBuf::from(&args[0]);
    let out = PathBuf::from(&args[1]);
    let frames: Vec<u32> = args[2..]
        .iter()
        .map(|s| s.parse().context("frame number"))
        .collect::<Result<_>>()?;
    std::fs::create_dir_all(&out)?;
    let truth = Truth::load(&haul.join("truth.json"))?;
    let setup = prepare(&haul, &TrackOptions::default())?;
    let cfg = setup.pipeline_config();
    let g = setup.geometry;
    std::fs::write(
        out.join("geometry.txt"),
        format!(
            "{} {} {} {} {}\n",
            g.f, g.cx, g.cy, g.cx_right, g.baseline_mm
        ),
    )?;
    let mut pipe = new_pipeline(&setup)?;
    let mut ws = vec![
        0u8;
        fishtrack_core::pipeline::DefaultPipeline::workspace_size(
            setup.width as usize,
            setup.height as usize
        )
    ];
    let last = frames.iter().copied().max().unwrap_or(0);
    for pair in setup.haul.frames.iter().take(last as usize) {
        let (l, r) = setup.rectified(pair)?;
        let (lv, rv) = views(&l, &r)?;
        pipe.process_frame(pair.index, lv, rv, &mut ws, &mut |_| {})
            .map_err(|e| anyhow::anyhow!("frame {}: {e}", pair.index))?;
        if !frames.contains(&pair.index) {
            continue;
        }
        // the stereo stages again, timed, on the pipeline's own objects
        let (lo, ro) = (pipe.left_objects(), pipe.right_objects());
        let t0 = Instant::now();
        let pairs = pair_objects(&lv, &rv, lo, ro, &cfg.geometry, &cfg.pairing)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let pair_s = t0.elapsed().as_secs_f64();
        let mut ops = pairs.stats.sad_ops;
        let mut lengths = Vec::new();
        for p in pairs.pairs.iter() {
            let m = measure_length::<64, 16384, REFINE_BLOCKS>(
                &lv,
                &rv,
                lo,
                ro,
                p,
                &cfg.geometry,
                &cfg.params,
                &cfg.length,
            );
            if let Ok(m) = &m {
                ops += m.sad_ops;
            }
            lengths.push((p.left as usize, m.ok()));
        }
        let secs = t0.elapsed().as_secs_f64();
        let mut boxes = Vec::new();
        for (i, o) in lo.items.iter().enumerate() {
            let raw = raw_box(&setup.rectifier.left, &o.bbox);
            let fish = truth.fish.iter().find(|f| {
                f.frames.iter().any(|a| {
                    a.frame == pair.index
                        && a.inside_left
                        && a.inside_right
                        && a.left_box.is_some_and(|b| iou(b, raw) >= 0.4)
                })
            });
            let Some(fish) = fish else { continue };
            let core = lengths
                .iter()
                .find(|(k, _)| *k == i)
                .and_then(|(_, m)| m.filter(|m| m.consistent))
                .map(|m| m.length_mm as f64);
            boxes.push(serde_json::json!({
                "id": fish.id,
                "bbox": [o.bbox.x, o.bbox.y, o.bbox.w, o.bbox.h],
                "length_mm": fish.length_mm,
                "core_length_mm": core,
            }));
        }
        let stem = format!("{:06}", pair.index);
        l.save(out.join(format!("{stem}_left.png")))?;
        r.save(out.join(format!("{stem}_right.png")))?;
        std::fs::write(
            out.join(format!("{stem}_boxes.json")),
            serde_json::to_string_pretty(&boxes)?,
        )?;
        println!(
            "{{\"frame\": {}, \"pair_s\": {pair_s}, \"pair_sad_ops\": {}, \"core_s\": {secs}, \"core_sad_ops\": {ops}, \"objects\": {}}}",
            pair.index,
            pairs.stats.sad_ops,
            boxes.len()
        );
    }
    Ok(())
}
