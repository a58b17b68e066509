//! `fishtrack`: count, track and measure fish in Cam-trawl stereo hauls.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use fishtrack::error::exit_code;

#[derive(Parser)]
#[command(
    name = "fishtrack",
    version,
    about = "Count, track and measure live fish in Cam-trawl stereo hauls"
)]
struct Cli {
    /// More log output on stderr (-v info, -vv debug, -vvv trace).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// No progress bars, errors only on stderr.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Synthesise a haul with ground truth, track it, score it, print a summary.
    Demo {
        /// Where to write the haul and the results (default: a temporary folder).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Write a synthetic haul (left/, right/, calibration.yml) and its truth.json.
    Synth {
        /// Output haul directory.
        dir: PathBuf,
        /// Number of stereo frame pairs.
        #[arg(long, default_value_t = 30)]
        frames: u32,
        /// Random seed (same seed, same bytes).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Frame width and height in pixels.
        #[arg(long, default_value_t = 2048)]
        size: u32,
        /// Mean number of fish entering the view per frame.
        #[arg(long, default_value_t = 1.0)]
        fish_rate: f64,
    },
    /// Track fish in a haul and write tracks, fish, detections and summary.
    Track {
        /// Haul directories (several: one subfolder of OUT each).
        #[arg(required = true)]
        haul: Vec<PathBuf>,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// TOML file overriding Table I parameters.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Also write overlays and the length-frequency plot.
        #[arg(long)]
        overlays: bool,
        /// Data association: viterbi, mc or nn (default: the parameters', viterbi).
        #[arg(long)]
        tracker: Option<String>,
        /// Rectification free scaling (OpenCV stereoRectify alpha; default
        /// `canvas`: 0.25's scale on a frame large enough to keep every raw
        /// pixel, the views' edges filled with water): a number keeps the
        /// raw frame's size, 0 keeps only valid pixels, 1 the whole raw
        /// views, -1 is OpenCV's default scaling, `auto` is 0.25 unless that
        /// magnifies the raw views, then the least scale that does not.
        #[arg(long, allow_negative_numbers = true, value_parser = parse_rect_alpha)]
        rect_alpha: Option<fishtrack::rectify::Scaling>,
        /// The haul's frame rate, frames per second (default 5, the
        /// Cam-trawl's). It scales a newborn fish's first predicted step
        /// (fish cross the view in about 4.3 frames at 5 fps) and is
        /// written to the VIAME CSV.
        #[arg(long)]
        fps: Option<f64>,
    },
    /// Score a tracker output directory against HAUL/truth.json.
    Eval {
        /// Haul directory with truth.json.
        haul: PathBuf,
        /// Tracker output directory.
        out: PathBuf,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Compare the no-heap core with the float reference on a haul.
    Compare {
        /// Haul directory.
        haul: PathBuf,
        /// Rectification free scaling, as for `track` (default `canvas`).
        #[arg(long, allow_negative_numbers = true, value_parser = parse_rect_alpha)]
        rect_alpha: Option<fishtrack::rectify::Scaling>,
        /// The haul's frame rate, as for `track` (default 5).
        #[arg(long)]
        fps: Option<f64>,
    },
    /// Per-stage timing, pairs per second and memory on a haul.
    Bench {
        /// Haul directory.
        haul: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// Repeated runs (medians are reported).
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// Only the first N frame pairs.
        #[arg(long)]
        frames: Option<usize>,
        /// Rectification free scaling, as for `track` (default `canvas`).
        #[arg(long, allow_negative_numbers = true, value_parser = parse_rect_alpha)]
        rect_alpha: Option<fishtrack::rectify::Scaling>,
    },
    /// Strobe/camera timing bench check over a serial line.
    TimingCheck {
        /// Serial port path.
        #[arg(long)]
        port: PathBuf,
        /// Frames to run.
        #[arg(long, default_value_t = 25)]
        frames: u32,
    },
}

/// `--rect-alpha auto|canvas|A` ([`fishtrack::track_cmd::parse_scaling`]).
fn parse_rect_alpha(s: &str) -> Result<fishtrack::rectify::Scaling, String> {
    fishtrack::track_cmd::parse_scaling(s).map_err(|e| e.to_string())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Demo { out } => fishtrack::demo_cmd::run(out),
        Command::Synth {
            dir,
            frames,
            seed,
            size,
            fish_rate,
        } => {
            let config = fishtrack::synth::SynthConfig {
                frames,
                seed,
                size,
                fish_rate,
            };
            let truth = fishtrack::synth::write_haul(&dir, &config)?;
            fishtrack::outln!(
                "wrote {} frame pairs ({}x{}, seed {}) with {} fish to {}",
                truth.frames,
                truth.width,
                truth.height,
                truth.seed,
                truth.fish.len(),
                dir.display()
            )?;
            Ok(())
        }
        Command::Track {
            haul,
            out,
            params,
            overlays,
            tracker,
            rect_alpha,
            fps,
        } => fishtrack::track_cmd::run(
            &haul,
            &out,
            &fishtrack::track_cmd::TrackOptions {
                params,
                tracker,
                overlays,
                rect_alpha,
                fps,
            },
        ),
        Command::Eval { haul, out, json } => {
            let report = fishtrack::eval::evaluate(&haul, &out)?;
            if json {
                fishtrack::outln!("{}", report.json())?;
            } else {
                fishtrack::out!("{}", report.table())?;
            }
            Ok(())
        }
        Command::Compare {
            haul,
            rect_alpha,
            fps,
        } => fishtrack::compare_cmd::run(&haul, rect_alpha, fps),
        Command::Bench {
            haul,
            json,
            repeats,
            frames,
            rect_alpha,
        } => fishtrack::bench_cmd::run(
            &haul,
            json,
            &fishtrack::bench_cmd::BenchOptions {
                repeats,
                frames,
                rect_alpha,
            },
        ),
        Command::TimingCheck { port, frames } => fishtrack::timing::run(&port, frames),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    fishtrack::progress::init(cli.verbose, cli.quiet);
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(exit_code(&e) as u8)
        }
    }
}
