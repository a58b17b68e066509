//! Runs the whole core pipeline ([`fishtrack_core::pipeline::Pipeline`]) on
//! one rectified frame pair of a haul, frames already in memory, for
//! instruction counting (`scripts/callgrind.sh` collects only inside
//! `process_frame`) and profiling.
//!
//! `core_pair HAUL [--frame N] [--reps K]`: frame N (default: the middle
//! one), processed K times (default 1) by a fresh pipeline each time.
//! `core_pair HAUL --all [--reps K]`: every pair of the haul rectified into
//! memory first, then the whole haul through one pipeline, K times — the
//! core's work as `bench` times it, for `perf record` or callgrind of the
//! core alone over a haul.

use anyhow::{Context, Result};
use fishtrack::track_cmd::{new_pipeline, prepare, views, TrackOptions};
use fishtrack_core::pipeline::DefaultPipeline;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let haul = args
        .first()
        .context("usage: core_pair HAUL [--frame N] [--reps K]")?;
    let opt = |name: &str| -> Option<usize> {
        let i = args.iter().position(|a| a == name)?;
        args.get(i + 1)?.parse().ok()
    };
    let setup = prepare(std::path::Path::new(haul), &TrackOptions::default())?;
    if args.iter().any(|a| a == "--all") {
        return whole_haul(&setup, opt("--reps").unwrap_or(1));
    }
    let n = setup.haul.frames.len();
    let k = opt("--frame").unwrap_or(n.div_ceil(2)).clamp(1, n.max(1));
    let reps = opt("--reps").unwrap_or(1);
    let pair = &setup.haul.frames[k - 1];
    let (l, r) = setup.rectified(pair)?;
    let (lv, rv) = views(&l, &r)?;
    let (w, h) = (setup.width as usize, setup.height as usize);
    let mut ws = vec![0u8; DefaultPipeline::workspace_size(w, h)];
    let mut events = 0usize;
    let t = std::time::Instant::now();
    for _ in 0..reps {
        let mut pipe = new_pipeline(&setup)?;
        pipe.process_frame(pair.index, lv, rv, &mut ws, &mut |_| events += 1)
            .map_err(|e| anyhow::anyhow!("frame {}: {e}", pair.index))?;
    }
    let dt = t.elapsed().as_secs_f64() / reps.max(1) as f64;
    println!(
        "frame {} ({w}x{h}): {:.2} ms per pair, {events} events, {} pixels per pair",
        pair.index,
        dt * 1e3,
        2 * w * h
    );
    Ok(())
}

/// Every pair of the haul, frames in memory, through one pipeline `reps` times.
fn whole_haul(setup: &fishtrack::track_cmd::Setup, reps: usize) -> Result<()> {
    let mut frames = Vec::new();
    for pair in &setup.haul.frames {
        frames.push((pair.index, setup.rectified(pair)?));
    }
    let (w, h) = (setup.width as usize, setup.height as usize);
    let mut ws = vec![0u8; DefaultPipeline::workspace_size(w, h)];
    let mut events = 0usize;
    let t = std::time::Instant::now();
    for _ in 0..reps {
        let mut pipe = new_pipeline(setup)?;
        for (index, (l, r)) in &frames {
            let (lv, rv) = views(l, r)?;
            pipe.process_frame(*index, lv, rv, &mut ws, &mut |_| events += 1)
                .map_err(|e| anyhow::anyhow!("frame {index}: {e}"))?;
        }
    }
    let pairs = (frames.len() * reps.max(1)) as f64;
    let dt = t.elapsed().as_secs_f64();
    println!(
        "{} pairs ({w}x{h}): {:.2} ms per pair, {:.1} pairs/s, {events} events, {} pixels per pair",
        frames.len(),
        dt * 1e3 / pairs,
        pairs / dt,
        2 * w * h
    );
    Ok(())
}
