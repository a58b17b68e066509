//! Ignored helpers run on purpose: the README montage
//! (`cargo test -p fishtrack --release --test synth_tools write_readme_montage -- --ignored`)
//! and the hardness figures
//! (`cargo test -p fishtrack --release --test synth_tools hardness_report -- --ignored --nocapture`).

use std::path::Path;

use fishtrack::synth::montage::write_montage;
use fishtrack::synth::SynthConfig;

#[test]
#[ignore = "writes docs/synthetic_montage.png"]
fn write_readme_montage() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/synthetic_montage.png");
    let config = SynthConfig {
        frames: 13,
        seed: 2,
        size: 2048,
        fish_rate: 1.0,
    };
    write_montage(&path, config, &[11, 12, 13], 512).unwrap();
    assert!(path.exists());
}

/// Prints NN hardness (see `fishtrack::synth::hardness`) for seeds
/// `FISHTRACK_SEEDS` (default 1..=5) at `FISHTRACK_SIZE` (default 2048),
/// 30 frames each, rendered in a temporary folder.
#[test]
#[ignore = "measurement: prints the hardness figures for the report"]
fn hardness_report() {
    let size: u32 = std::env::var("FISHTRACK_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2048);
    let seeds: Vec<u64> = std::env::var("FISHTRACK_SEEDS")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or_else(|| (1..=5).collect());
    for seed in seeds {
        let d = tempfile::tempdir().unwrap();
        let config = SynthConfig {
            frames: 30,
            seed,
            size,
            fish_rate: 1.0,
        };
        let t = fishtrack::synth::write_haul(d.path(), &config).unwrap();
        let h = fishtrack::synth::hardness::hardness(&t);
        println!(
            "size {size} seed {seed}: fish {} life {:.2} per-frame {:.2} NN default {:.3} best {:.3} (gate {:.0} px, alpha {}, coast {})",
            h.fish, h.mean_life, h.mean_per_frame, h.default_rate, h.best_rate, h.best.gate, h.best.alpha, h.best.max_missed
        );
    }
}
