//! `fishtrack demo [--out DIR]`: synthesises a small haul with ground truth
//! (1024 × 1024, 40 frame pairs), tracks it with the whole pipeline
//! ([`crate::track_cmd`]), scores it ([`crate::eval`]) and prints the table
//! and a short summary (fish counted vs true, per-fish length MAPE).

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::synth::{write_haul, SynthConfig};
use crate::track_cmd::{track_haul, TrackOptions};

/// Frame size of the demo haul.
pub const DEMO_SIZE: u32 = 1024;
/// Frame pairs of the demo haul.
pub const DEMO_FRAMES: u32 = 40;

/// Runs the demo; the haul goes to `DIR/haul`, the results to `DIR/out`
/// (a temporary folder, removed afterwards, when `out` is `None`).
pub fn run(out: Option<PathBuf>) -> Result<()> {
    let tmp;
    let base = match out {
        Some(d) => d,
        None => {
            tmp = tempfile::tempdir().context("cannot create a temporary folder")?;
            tmp.path().to_path_buf()
        }
    };
    let haul = base.join("haul");
    let res = base.join("out");
    let cfg = SynthConfig {
        frames: DEMO_FRAMES,
        seed: 1,
        size: DEMO_SIZE,
        fish_rate: 1.0,
    };
    let truth = write_haul(&haul, &cfg)?;
    crate::outln!(
        "synthesised {} frame pairs ({}x{}) with {} fish in {}",
        truth.frames,
        truth.width,
        truth.height,
        truth.fish.len(),
        haul.display()
    )?;
    let o = track_haul(&haul, &res, &TrackOptions::default())?;
    crate::outln!(
        "tracked: {} fish ({} with a length), {:.2} s per frame pair → {}",
        o.fish,
        o.measured,
        o.seconds_per_frame,
        res.display()
    )?;
    let report = crate::eval::evaluate(&haul, &res)?;
    crate::out!("{}", report.table())?;
    if let Some(t) = &report.tracking {
        crate::outln!(
            "summary: {} fish counted, {} true (count error {:+.1} %)",
            t.count.tracks,
            t.count.fish,
            100.0 * t.count.error
        )?;
        match &t.length {
            Some(l) => crate::outln!(
                "summary: per-fish length MAPE {:.2} % over {}/{} fish measured",
                100.0 * l.mape,
                l.measured,
                l.measurable
            )?,
            None => crate::outln!("summary: no fish length to score")?,
        }
    }
    Ok(())
}
