//! `fishtrack track HAUL... --out OUT`: the main job (DESIGN.md, "Output").
//!
//! Per haul: open it, load the calibration (frame size from the first frame
//! where the layout lacks it), build the rectification maps, the Table I
//! parameters (`Params::for_frame(width)` or `--params FILE`, then
//! `--tracker`), and run every frame pair through read → rectify →
//! [`fishtrack_core::pipeline::Pipeline`] (paper Fig. 6). The pipeline's
//! rectified boxes are mapped back into the raw images
//! ([`RectifiedCamera::rect_box_to_raw`]) and its 3-D points from the
//! rectified into the raw left camera frame (`R1ᵀ·X`), in mm. Writes
//! `tracks.csv`, `fish.csv`, `detections.csv`, `detections.viame.csv`,
//! `stereo.csv`, with `--overlays` the pictures of [`crate::overlay`] and
//! the plot of [`crate::plot`], and `summary.json` last, as the completion
//! marker (atomic, deterministic apart from the timings in `summary.json`).
//! Several hauls: [`crate::survey`].
//!
//! A track the tracker closed as a duplicate of another (same fish counted
//! twice, see `core::track`) is not a fish: its rows are left out of
//! `tracks.csv`, `fish.csv` and the VIAME file and counted in the summary.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use image::GrayImage;
use nalgebra::{Matrix3x4, Vector3};
use serde_json::json;

use crate::columns::ColumnOffsets;
use crate::params_file::TrackOverrides;
use fishtrack_core::geometry::StereoGeometry;
use fishtrack_core::image::Roi;
use fishtrack_core::params::{Params, Tracker as Association};
use fishtrack_core::pipeline::{
    DefaultPipeline, PipelineConfig, PipelineEvent, PipelineStats, Stage,
};
use fishtrack_core::track::CloseReason;
use fishtrack_core::ImageView;

use crate::calib::StereoCalib;
use crate::error::InputError;
use crate::haul::{FramePair, Haul};
use crate::output::{
    write_detections, write_fish, write_json, write_stereo, write_tracks, write_viame,
    DetectionRow, FishOut, StereoRow, TrackRow,
};
use crate::rectify::{in_raw_view, RectifiedCamera, Rectifier, Scaling};

/// Frames per second of Cam-trawl video (paper Section II): the default
/// of `--fps`.
pub const FPS: f64 = 5.0;

/// Checks `--fps`: a frame rate in (0, 1000] frames per second.
pub fn check_fps(fps: f64) -> Result<f64, InputError> {
    if fps.is_finite() && fps > 0.0 && fps <= 1000.0 {
        Ok(fps)
    } else {
        Err(InputError::plain(
            "--fps",
            format!("{fps} is not a frame rate in (0, 1000] frames per second"),
        ))
    }
}

/// Command-line options of `fishtrack track`.
#[derive(Debug, Clone, Default)]
pub struct TrackOptions {
    /// `--params FILE`.
    pub params: Option<PathBuf>,
    /// `--tracker viterbi|mc|nn`.
    pub tracker: Option<String>,
    /// `--overlays`.
    pub overlays: bool,
    /// `--rect-alpha auto|A`: the rectification's free scaling
    /// ([`Scaling::default`] when absent).
    pub rect_alpha: Option<Scaling>,
    /// `--fps F`: the haul's frame rate ([`FPS`] when absent).
    pub fps: Option<f64>,
}

/// A haul made ready for the pipeline.
pub struct Setup {
    /// The haul.
    pub haul: Haul,
    /// Rectification maps and cameras.
    pub rectifier: Rectifier,
    /// Parameters in use.
    pub params: Params,
    /// Rectified stereo geometry.
    pub geometry: StereoGeometry,
    /// Rectified frame width (the pipeline's frames).
    pub width: u32,
    /// Rectified frame height.
    pub height: u32,
    /// Raw frame width (the calibration's).
    pub raw_width: u32,
    /// Raw frame height.
    pub raw_height: u32,
    /// Column fixed-pattern offsets of the left and right cameras
    /// ([`crate::columns`]), taken out of every raw frame.
    pub columns: [Option<ColumnOffsets>; 2],
    /// The params file's `[track]` overrides (applied last by
    /// [`Setup::pipeline_config`]).
    pub track: TrackOverrides,
    /// The haul's frame rate, frames per second (`--fps`).
    pub fps: f64,
}

/// [`TrackConfig::crossing_width`](fishtrack_core::track::TrackConfig::crossing_width)
/// for raw views `raw_width` pixels wide filmed at `fps`: the width a fish
/// crosses in the paper's 4.3-frame lifespan, which it measured at 5 fps
/// (Section II). At a lower frame rate a fish swimming at the same speed
/// moves further per frame, so the 4.3 frames span `5 / fps` views (at
/// 2.5 fps a fish crosses the view in about two frames). Clamped to
/// the tracker's 1–32 000 px.
pub fn crossing_width(raw_width: u32, fps: f64) -> u32 {
    (f64::from(raw_width) * FPS / fps)
        .round()
        .clamp(1.0, 32_000.0) as u32
}

/// [`TrackConfig::max_lost`](fishtrack_core::track::TrackConfig::max_lost)
/// for a haul filmed at `fps`: its default (1 lost frame) was chosen at
/// 5 fps, where a fish carried through one lost frame moves about a
/// quarter of the view. At a lower rate one lost frame carries it
/// `5 / fps` times as far (half the view at 2.5 fps, where a fish
/// crosses in two frames), so the tracker carries a lost fish through
/// at most `⌊fps / 5⌋` frames: never farther than at 5 fps (0 at
/// 2.5 fps, 2 at 10 fps; at most `depth − 2`). A params file's
/// `[track] max_lost` overrides it.
pub fn max_lost_for(fps: f64, depth: usize) -> u8 {
    let n = (fps / FPS).floor();
    let cap = depth.saturating_sub(2).min(u8::MAX as usize) as f64;
    if n.is_finite() && n > 0.0 {
        n.min(cap) as u8
    } else {
        0
    }
}

/// Parses `--tracker`.
pub fn parse_tracker(s: &str) -> Result<Association, InputError> {
    match s.to_ascii_lowercase().as_str() {
        "viterbi" => Ok(Association::Viterbi),
        "mc" => Ok(Association::Mc),
        "nn" => Ok(Association::Nn),
        _ => Err(InputError::plain(
            "--tracker",
            format!("`{s}` is not one of viterbi, mc, nn"),
        )),
    }
}

/// Checks `--rect-alpha`: `auto` ([`Scaling::NoMagnification`]), `canvas`
/// ([`Scaling::Canvas`]) or
/// OpenCV's free scaling in `[0, 1]`, or
/// negative for its default scaling (taken as −1).
pub fn parse_scaling(s: &str) -> Result<Scaling, InputError> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(Scaling::NoMagnification);
    }
    if s.trim().eq_ignore_ascii_case("canvas") {
        return Ok(Scaling::Canvas);
    }
    let a: f64 = s.trim().parse().map_err(|_| {
        InputError::plain(
            "--rect-alpha",
            format!("`{s}` is neither `auto`, `canvas` nor a number"),
        )
    })?;
    check_alpha(a).map(Scaling::Alpha)
}

/// Checks a numeric `--rect-alpha`: OpenCV's free scaling is in `[0, 1]`,
/// or negative for its default scaling (taken as −1).
pub fn check_alpha(a: f64) -> Result<f64, InputError> {
    if a.is_finite() && a <= 1.0 {
        Ok(if a < 0.0 { -1.0 } else { a })
    } else {
        Err(InputError::plain(
            "--rect-alpha",
            format!("{a} is not in [0, 1] (or negative for OpenCV's default scaling)"),
        ))
    }
}

#[cfg(test)]
mod fps_tests {
    use super::*;

    #[test]
    fn max_lost_follows_the_frame_rate() {
        let d = fishtrack_core::track::DefaultTracker::DEPTH;
        // the tracker's own default at the paper's rate
        assert_eq!(
            max_lost_for(FPS, d),
            fishtrack_core::track::TrackConfig::for_frame(2048, 2048).max_lost
        );
        assert_eq!(max_lost_for(2.5, d), 0);
        assert_eq!(max_lost_for(4.99, d), 0);
        assert_eq!(max_lost_for(10.0, d), 2);
        assert_eq!(max_lost_for(1000.0, d), (d - 2) as u8);
        assert_eq!(max_lost_for(1000.0, 1), 0);
        assert_eq!(max_lost_for(f64::NAN, d), 0);
    }

    #[test]
    fn crossing_width_follows_the_frame_rate() {
        assert_eq!(crossing_width(2048, FPS), 2048);
        assert_eq!(crossing_width(2048, 2.5), 4096);
        assert_eq!(crossing_width(2048, 10.0), 1024);
        assert_eq!(crossing_width(1000, 3.0), 1667);
        // clamped to what the tracker accepts
        assert_eq!(crossing_width(2048, 0.001), 32_000);
        assert_eq!(crossing_width(1, 1000.0), 1);
        for ok in [0.1, 2.5, 5.0, 1000.0] {
            assert_eq!(check_fps(ok).unwrap(), ok);
        }
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1000.5] {
            let e = check_fps(bad).unwrap_err().to_string();
            assert!(e.contains("--fps") && e.contains("frame rate"), "{e}");
        }
    }
}

#[cfg(test)]
mod alpha_tests {
    #[test]
    fn rect_alpha_is_checked() {
        assert_eq!(super::check_alpha(0.25).unwrap(), 0.25);
        assert_eq!(super::check_alpha(-3.0).unwrap(), -1.0);
        for bad in [1.5, f64::NAN, f64::INFINITY] {
            let e = super::check_alpha(bad).unwrap_err().to_string();
            assert!(e.contains("--rect-alpha"), "{e}");
        }
        use crate::rectify::Scaling;
        assert_eq!(
            super::parse_scaling("auto").unwrap(),
            Scaling::NoMagnification
        );
        assert_eq!(super::parse_scaling(" Canvas").unwrap(), Scaling::Canvas);
        assert_eq!(super::parse_scaling(" 0.5").unwrap(), Scaling::Alpha(0.5));
        assert_eq!(super::parse_scaling("-2").unwrap(), Scaling::Alpha(-1.0));
        for bad in ["1.5", "fast", ""] {
            let e = super::parse_scaling(bad).unwrap_err().to_string();
            assert!(e.contains("--rect-alpha"), "{e}");
        }
    }
}

/// Opens `dir` and prepares calibration, rectification, parameters and geometry.
pub fn prepare(dir: &Path, opts: &TrackOptions) -> Result<Setup> {
    let haul = Haul::open(dir)?;
    let first = haul
        .frames
        .first()
        .ok_or_else(|| InputError::file(dir.join("left"), "the haul has no frames"))?;
    let size = image::image_dimensions(&first.left).map_err(|e| {
        InputError::file(
            &first.left,
            format!("frame {}: cannot read: {e}", first.index),
        )
    })?;
    haul.calibration()?;
    let calib = StereoCalib::load(&haul.dir, Some(size))?;
    let rectifier = Rectifier::with_scaling(&calib, opts.rect_alpha.unwrap_or_default());
    if rectifier.rect.vertical {
        return Err(InputError::file(
            &haul.dir,
            "calibration has a vertical baseline; only side-by-side rigs are supported",
        )
        .into());
    }
    let p1: Matrix3x4<f32> = rectifier.rect.p1.cast();
    let p2: Matrix3x4<f32> = rectifier.rect.p2.cast();
    let geometry = StereoGeometry::from_projections(&p1, &p2).map_err(|e| {
        InputError::file(
            &haul.dir,
            format!("calibration gives no usable stereo geometry: {e:?}"),
        )
    })?;
    let (width, height) = (calib.width, calib.height);
    // pixel-valued parameters follow the raw frame's scale, which every
    // rectification keeps to within a few per cent
    let (mut params, track) = match &opts.params {
        Some(p) => {
            let f = crate::params_file::load_params(p, width)?;
            (f.params, f.track)
        }
        None => (Params::for_frame(width), TrackOverrides::default()),
    };
    if let Some(t) = &opts.tracker {
        params.tracker = parse_tracker(t)?;
    }
    params
        .validate()
        .map_err(|e| InputError::plain("parameters", format!("{e}")))?;
    // the cameras' column offsets, from frames spread over the haul
    // (decoded in parallel; the 16-bit warning and an error name the first
    // such file in frame order, so they are the same on every run: rayon's
    // collect into a `Result` returns whichever error a thread met first)
    let pairs: Vec<(GrayImage, GrayImage, Option<&std::path::Path>)> = {
        use rayon::prelude::*;
        let loaded: Vec<_> =
            crate::columns::spread(haul.frames.len(), crate::columns::SAMPLE_FRAMES)
                .into_par_iter()
                .map(|i| haul.load_pair_quiet(&haul.frames[i], Some((width, height))))
                .collect();
        loaded.into_iter().collect::<Result<_, _>>()?
    };
    if let Some(path) = pairs.iter().find_map(|p| p.2) {
        haul.warn_16bit(path);
    }
    let (lefts, rights): (Vec<GrayImage>, Vec<GrayImage>) =
        pairs.into_iter().map(|(l, r, _)| (l, r)).unzip();
    let columns = [
        ColumnOffsets::estimate(&lefts),
        ColumnOffsets::estimate(&rights),
    ];
    for (cam, c) in ["left", "right"].iter().zip(&columns) {
        if let Some(c) = c.as_ref().filter(|c| c.applied.is_some()) {
            log::info!(
                "{cam} camera: column offsets of RMS {:.2} grey levels taken out",
                c.rms
            );
        }
    }
    let fps = check_fps(opts.fps.unwrap_or(FPS))?;
    let (rect_width, rect_height) = rectifier.size();
    Ok(Setup {
        haul,
        rectifier,
        params,
        geometry,
        width: rect_width,
        height: rect_height,
        raw_width: width,
        raw_height: height,
        columns,
        track,
        fps,
    })
}

impl Setup {
    /// The pipeline configuration of this haul.
    pub fn pipeline_config(&self) -> PipelineConfig {
        let mut cfg = PipelineConfig::new(self.params, self.geometry, self.width, self.height);
        cfg.valid = self.rectifier.valid_rois();
        // the tracker's frame border is the raw view's (TrackConfig::view)
        cfg.track.view = self.rectifier.view_rois();
        cfg.track.outline = self.rectifier.view_outlines();
        // the cues' σ and a newborn's default velocity follow the raw
        // views' scale, not a canvas's size
        cfg.track.sigma_defaults = fishtrack_core::track::Sigmas::for_frame(self.raw_width);
        cfg.track.crossing_width = crossing_width(self.raw_width, self.fps);
        cfg.track.max_lost = max_lost_for(self.fps, fishtrack_core::track::DefaultTracker::DEPTH);
        self.track.apply(&mut cfg.track);
        cfg
    }

    /// Loads one raw frame pair, the cameras' column offsets taken out.
    pub fn load_pair(&self, pair: &FramePair) -> Result<(GrayImage, GrayImage)> {
        let (mut l, mut r) = self
            .haul
            .load_pair(pair, Some((self.raw_width, self.raw_height)))?;
        for (img, c) in [&mut l, &mut r].into_iter().zip(&self.columns) {
            if let Some(c) = c {
                c.apply(img);
            }
        }
        Ok((l, r))
    }

    /// Loads and rectifies one frame pair.
    pub fn rectified(&self, pair: &FramePair) -> Result<(GrayImage, GrayImage)> {
        let (l, r) = self.load_pair(pair)?;
        let out = self.rectifier.rectify_pair(&l, &r).map_err(|e| {
            InputError::file(
                &pair.left,
                format!("frame {}: cannot rectify: {e:?}", pair.index),
            )
        })?;
        Ok(out)
    }
}

/// A new boxed default pipeline for `setup`.
pub fn new_pipeline(setup: &Setup) -> Result<Box<DefaultPipeline>> {
    let p = DefaultPipeline::new(setup.pipeline_config())
        .map_err(|e| InputError::plain("pipeline configuration", format!("{e}")))?;
    Ok(Box::new(p))
}

/// Runs `f` on image views of two rectified frames.
pub fn views<'a>(l: &'a GrayImage, r: &'a GrayImage) -> Result<(ImageView<'a>, ImageView<'a>)> {
    let lv = ImageView::packed(l.as_raw(), l.width() as usize, l.height() as usize)
        .map_err(|e| anyhow::anyhow!("left view: {e:?}"))?;
    let rv = ImageView::packed(r.as_raw(), r.width() as usize, r.height() as usize)
        .map_err(|e| anyhow::anyhow!("right view: {e:?}"))?;
    Ok((lv, rv))
}

/// A rectified upright box → `[x, y, w, h]` in the camera's raw pixels
/// ([`RectifiedCamera::raw_box`]).
pub fn raw_box(cam: &RectifiedCamera, b: &Roi) -> [f64; 4] {
    cam.raw_box(b)
}

/// A rectified-frame 3-D point → raw left camera frame.
pub fn raw_point(rect: &Rectifier, p: &[f32; 3]) -> [f64; 3] {
    let v = rect.rect.r1.transpose() * Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
    [v.x, v.y, v.z]
}

/// What one haul gave.
#[derive(Debug, Clone)]
pub struct HaulOutcome {
    /// Fish counted.
    pub fish: usize,
    /// Fish with a length.
    pub measured: usize,
    /// Frames processed.
    pub frames: u32,
    /// Seconds spent per frame (all stages, read and rectify included).
    pub seconds_per_frame: f64,
    /// Lengths of the measured fish, mm (`fish.csv` order).
    pub lengths: Vec<f64>,
}

const STAGES: [&str; 7] = [
    "read",
    "rectify",
    "segment_left",
    "segment_right",
    "pair",
    "length",
    "track",
];

fn stage_index(s: Stage) -> usize {
    match s {
        Stage::SegmentLeft => 2,
        Stage::SegmentRight => 3,
        Stage::Pair => 4,
        Stage::Length => 5,
        Stage::Track => 6,
    }
}

/// Tracks one haul into `out` (created if needed).
pub fn track_haul(dir: &Path, out: &Path, opts: &TrackOptions) -> Result<HaulOutcome> {
    let setup = prepare(dir, opts)?;
    crate::survey::prepare_out_dir(out)?;
    log::info!(
        "{}: {} frame pairs {}x{}, tracker {:?}, output {}",
        dir.display(),
        setup.haul.frames.len(),
        setup.width,
        setup.height,
        setup.params.tracker,
        out.display()
    );
    log::debug!("{}: parameters {:?}", dir.display(), setup.params);
    let bar = crate::progress::bar(
        setup.haul.frames.len() as u64,
        &crate::survey::short_name(dir),
        "frames",
    );
    let mut pipe = new_pipeline(&setup)?;
    let (w, h) = (setup.width as usize, setup.height as usize);
    let mut ws = vec![0u8; DefaultPipeline::workspace_size(w, h)];
    let mut events: Vec<PipelineEvent> = Vec::new();
    let mut secs = [0.0f64; STAGES.len()];
    let started = Instant::now();
    // FISHTRACK_STEREO_DIAG=1: every right object (analysis aid)
    let mut right_diag =
        std::env::var_os("FISHTRACK_STEREO_DIAG").map(|_| String::from("frame,x,y,w,h,area\n"));
    // the photometric map of each frame (right view to left, gain, offset)
    let mut maps: Vec<(f32, f32)> = Vec::new();
    // read + rectify run ahead on another thread (crate::frame_source)
    crate::frame_source::for_each_rectified(&setup, &setup.haul.frames, |rp| {
        let pair = rp.pair;
        secs[0] += rp.read_s;
        secs[1] += rp.rectify_s;
        let (lv, rv) = views(&rp.left, &rp.right)?;
        let mut last = Instant::now();
        pipe.process_frame(pair.index, lv, rv, &mut ws, &mut |e| {
            if let PipelineEvent::StageDone { stage, .. } = e {
                secs[stage_index(*stage)] += last.elapsed().as_secs_f64();
                last = Instant::now();
            } else {
                if let PipelineEvent::FrameDone { frame, counts } = e {
                    log::debug!(
                        "frame {frame}: {} left / {} right objects, {} pairs, {} measured, {} live tracks",
                        counts.left_objects,
                        counts.right_objects,
                        counts.pairs,
                        counts.measured,
                        counts.live_tracks
                    );
                }
                events.push(*e);
            }
        })
        .map_err(|e| {
            InputError::file(&pair.left, format!("frame {}: pipeline: {e}", pair.index))
        })?;
        let m = pipe.photometric();
        maps.push((m.gain, m.offset));
        log::debug!(
            "frame {}: right-to-left grey map gain {:.3}, offset {:.2}{}",
            pair.index,
            m.gain,
            m.offset,
            if m.is_identity() { " (identity)" } else { "" }
        );
        if let Some(d) = right_diag.as_mut() {
            for o in pipe.right_objects().items.iter() {
                let b = raw_box(&setup.rectifier.right, &o.bbox);
                d.push_str(&format!(
                    "{},{},{},{},{},{}\n",
                    pair.index, b[0], b[1], b[2], b[3], o.area
                ));
            }
        }
        bar.inc(1);
        Ok(())
    })?;
    if let Some(d) = right_diag {
        std::fs::write(out.join("right_objects_diag.csv"), d)?;
    }
    bar.finish_and_clear();
    let t = Instant::now();
    pipe.finish(&mut |e| events.push(*e));
    secs[6] += t.elapsed().as_secs_f64();
    let total = started.elapsed().as_secs_f64();
    let stats = pipe.stats();
    let frames = setup.haul.frames.len() as u32;
    let written = write_outputs(&setup, out, &events, opts)?;
    if opts.overlays {
        crate::overlay::write_all(&setup, out, &events, &written.fish)?;
        crate::plot::write_haul_plot(&setup.haul.dir, out, &written.fish)?;
    }
    let timings: BTreeMap<&str, f64> = STAGES.iter().copied().zip(secs).collect();
    // Last: summary.json marks the output folder complete.
    write_summary(&setup, out, &written, &stats, &timings, total, &maps)?;
    Ok(HaulOutcome {
        fish: written.fish.len(),
        measured: written
            .fish
            .iter()
            .filter(|f| f.length_mm.is_some())
            .count(),
        frames,
        seconds_per_frame: total / frames.max(1) as f64,
        lengths: written.fish.iter().filter_map(|f| f.length_mm).collect(),
    })
}

struct Written {
    fish: Vec<FishOut>,
    tracks: usize,
    detections: usize,
    stereo_rows: usize,
    duplicates: usize,
    /// Tentative tracks never confirmed (`TrackConfig::confirm_births`).
    unconfirmed: usize,
    /// Tracks whose every observed box in the raw view is under θ_A^L.
    slivers: usize,
    /// Counted fish whose measured frames disagree with no majority
    /// (length withheld, `LengthConfig::track_agreement`).
    inconsistent: usize,
}

fn write_outputs(
    setup: &Setup,
    out: &Path,
    events: &[PipelineEvent],
    _opts: &TrackOptions,
) -> Result<Written> {
    let rect = &setup.rectifier;
    let mut dets = Vec::new();
    let mut stereo = Vec::new();
    let mut tracks = Vec::new();
    let mut fish = Vec::new();
    let mut duplicates = BTreeSet::new();
    let mut unconfirmed = BTreeSet::new();
    let mut inconsistent = BTreeSet::new();
    // FISHTRACK_STEREO_DIAG=1: every pair's length measurement in
    // OUT/stereo_diag.csv (analysis aid, not part of the output contract)
    let mut diag = std::env::var_os("FISHTRACK_STEREO_DIAG").map(|_| String::new());
    for e in events {
        match *e {
            PipelineEvent::Object {
                frame,
                bbox,
                obb,
                stereo: st,
                ..
            } => {
                let lb = raw_box(&rect.left, &bbox);
                if !in_raw_view(&lb) {
                    // wholly in the fill of an alpha > 0 rectification
                    continue;
                }
                dets.push(DetectionRow {
                    frame,
                    bbox: lb,
                    conf: 1.0,
                    length_px: rect.left.raw_axis_length(&obb),
                });
                if let (Some(d), Some(s)) = (diag.as_mut(), st) {
                    diag_row(d, frame, &lb, &raw_box(&rect.right, &s.right_box), &s);
                }
                // lengths whose views disagree are withheld (core::length)
                let fl = st.and_then(|s| s.length).filter(|l| l.consistent);
                stereo.push(StereoRow::new(
                    frame,
                    lb,
                    st.map(|s| raw_box(&rect.right, &s.right_box)),
                    fl.map(|l| raw_point(rect, &l.ends[0].xyz)),
                    fl.map(|l| raw_point(rect, &l.ends[1].xyz)),
                    fl.map(|l| l.length_mm as f64),
                ));
            }
            PipelineEvent::TrackFrame {
                track,
                frame,
                obs,
                bbox,
                centre,
            } => tracks.push(TrackRow {
                frame,
                id: track,
                bbox: raw_box(&rect.left, &bbox),
                conf: if obs.is_some() { 1.0 } else { 0.5 },
                xyz: centre.map(|p| raw_point(rect, &p)),
            }),
            PipelineEvent::TrackClosed {
                track,
                reason,
                first_frame,
                last_frame,
                frames,
                length,
                range_mm,
                ..
            } => {
                log::debug!("track {track} closed ({reason:?}): frames {first_frame}–{last_frame}, {frames} observed");
                if reason == CloseReason::Duplicate {
                    duplicates.insert(track);
                    continue;
                }
                if reason == CloseReason::Unconfirmed {
                    unconfirmed.insert(track);
                    continue;
                }
                if length.inconsistent {
                    inconsistent.insert(track);
                }
                fish.push(FishOut {
                    track_id: track,
                    first_frame,
                    last_frame,
                    frames,
                    length_mm: length.median_mm.map(f64::from),
                    length_sd_mm: length.median_mm.map(|_| length.robust_sd_mm as f64),
                    range_mm: range_mm.map(f64::from),
                });
            }
            PipelineEvent::StageDone { .. } | PipelineEvent::FrameDone { .. } => {}
        }
    }
    // rows wholly in the fill (alpha > 0) are not in the raw view; a track
    // never in it is no fish
    tracks.retain(|r| in_raw_view(&r.bbox));
    // a fish is an object of at least θ_A^L pixels (eq. 4, `area_min` at
    // the raw frame's scale): a track whose every observed box inside the
    // raw view is smaller (a sliver at the raw edge, the rest of its
    // object in the fill, or a fragment of a fish leaving) never showed
    // one, and is not counted (seeds 1–30 / 31–60: 5 / 3 such tracks, all
    // one frame long, none a fish)
    let slivers = sliver_tracks(&tracks, f64::from(setup.params.area_min));
    tracks.retain(|r| !slivers.contains(&r.id));
    // a fish needs an observation in the raw view; its first/last observed
    // frame and its frame count (observed or predicted) come from the rows
    // still there (equal to the core's when no row was dropped)
    let mut seen: BTreeMap<u32, (u32, u32)> = BTreeMap::new();
    for r in tracks.iter().filter(|r| r.conf >= 1.0) {
        let e = seen.entry(r.id).or_insert((r.frame, r.frame));
        *e = (e.0.min(r.frame), e.1.max(r.frame));
    }
    let mut rows_of: BTreeMap<u32, u32> = BTreeMap::new();
    for r in &tracks {
        *rows_of.entry(r.id).or_insert(0) += 1;
    }
    fish.retain_mut(|f| match seen.get(&f.track_id) {
        Some(&(first, last)) if !duplicates.contains(&f.track_id) => {
            f.first_frame = first;
            f.last_frame = last;
            f.frames = rows_of.get(&f.track_id).copied().unwrap_or(0);
            true
        }
        _ => false,
    });
    tracks.retain(|r| !duplicates.contains(&r.id) && !unconfirmed.contains(&r.id));
    tracks.sort_by_key(|r| (r.frame, r.id));
    fish.sort_by_key(|f| f.track_id);
    let names: Vec<String> = setup.haul.frames.iter().map(|f| f.name.clone()).collect();
    write_tracks(&out.join("tracks.csv"), &tracks)?;
    write_fish(&out.join("fish.csv"), &fish)?;
    write_detections(&out.join("detections.csv"), &dets)?;
    write_viame(
        &out.join("detections.viame.csv"),
        &tracks,
        &fish,
        &names,
        setup.fps,
    )?;
    write_stereo(&out.join("stereo.csv"), &stereo)?;
    if let Some(d) = diag {
        std::fs::write(out.join("stereo_diag.csv"), d)?;
    }
    Ok(Written {
        tracks: tracks.len(),
        detections: dets.len(),
        stereo_rows: stereo.len(),
        duplicates: duplicates.len(),
        unconfirmed: unconfirmed.len(),
        slivers: slivers.len(),
        inconsistent: fish
            .iter()
            .filter(|f| inconsistent.contains(&f.track_id))
            .count(),
        fish,
    })
}

/// Tracks whose every observed row (`conf` 1; predicted rows are 0.5) has
/// a box of fewer than `amin` pixels: no frame of theirs can hold an
/// object of θ_A^L pixels, eq. (4).
fn sliver_tracks(rows: &[TrackRow], amin: f64) -> BTreeSet<u32> {
    let mut biggest: BTreeMap<u32, f64> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.conf >= 1.0) {
        let e = biggest.entry(r.id).or_insert(0.0);
        *e = e.max(r.bbox[2] * r.bbox[3]);
    }
    biggest
        .into_iter()
        .filter(|&(_, a)| a < amin)
        .map(|(id, _)| id)
        .collect()
}

/// One `stereo_diag.csv` line: frame, raw left and right boxes, then the
/// pair's `FishLength` fields (empty when not measured).
fn diag_row(
    out: &mut String,
    frame: u32,
    lb: &[f64; 4],
    rb: &[f64; 4],
    s: &fishtrack_core::pipeline::StereoInfo,
) {
    use std::fmt::Write as _;
    if out.is_empty() {
        out.push_str("frame,lx,ly,lw,lh,rx,ry,rw,rh,d_o,mu_sad,inside,measured,consistent,length_mm,blocks,slope,cz");
        for e in 0..2 {
            let _ = write!(
                out,
                ",e{e}_px,e{e}_py,e{e}_d,e{e}_mask_d,e{e}_dev,e{e}_z,e{e}_ratio,e{e}_mis,e{e}_comp,e{e}_pl,e{e}_pr,e{e}_touch"
            );
        }
        out.push_str(",searched\n");
    }
    let _ = write!(
        out,
        "{frame},{},{},{},{},{},{},{},{},{},{},{}",
        lb[0],
        lb[1],
        lb[2],
        lb[3],
        rb[0],
        rb[1],
        rb[2],
        rb[3],
        s.pair.d_o,
        s.pair.mu_sad,
        s.wholly_inside as u8
    );
    match s.length {
        Some(l) => {
            let _ = write!(
                out,
                ",1,{},{},{},{},{}",
                l.consistent as u8, l.length_mm, l.blocks, l.slope, l.centre[2]
            );
            for e in l.ends.iter() {
                let _ = write!(
                    out,
                    ",{},{},{},{},{},{},{},{},{},{},{},{}",
                    e.px.0,
                    e.px.1,
                    e.d,
                    e.mask_d,
                    e.mask_dev,
                    e.xyz[2],
                    e.sad_ratio,
                    e.mismatch as u8,
                    e.compensated as u8,
                    e.probe[0],
                    e.probe[1],
                    e.touches_other as u8
                );
            }
        }
        None => out.push_str(",0,,,,,,,,,,,,,,,,,,,,,,,,,,,,,"),
    }
    let _ = write!(out, ",{}", s.pair.searched as u8);
    out.push('\n');
}

fn write_summary(
    setup: &Setup,
    out: &Path,
    w: &Written,
    stats: &PipelineStats,
    timings: &BTreeMap<&str, f64>,
    total: f64,
    maps: &[(f32, f32)],
) -> Result<()> {
    // the tracker settings the run used (the rate's and the params file's)
    let track = setup.pipeline_config().track;
    let med = |f: fn(&(f32, f32)) -> f32| {
        (!maps.is_empty()).then(|| {
            crate::stats::median(&mut maps.iter().map(|m| f(m) as f64).collect::<Vec<_>>())
        })
    };
    let gain_median = med(|m| m.0);
    let offset_median = med(|m| m.1);
    let mut lengths: Vec<f64> = w.fish.iter().filter_map(|f| f.length_mm).collect();
    lengths.sort_by(|a, b| a.total_cmp(b));
    let n = lengths.len();
    let mean = if n > 0 {
        lengths.iter().sum::<f64>() / n as f64
    } else {
        0.0
    };
    let sd = if n > 1 {
        (lengths.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    } else {
        0.0
    };
    let median = match n {
        0 => None,
        _ if n % 2 == 1 => Some(lengths[n / 2]),
        _ => Some(0.5 * (lengths[n / 2 - 1] + lengths[n / 2])),
    };
    let frames = setup.haul.frames.len();
    let per_frame: BTreeMap<&str, f64> = timings
        .iter()
        .map(|(k, v)| (*k, v * 1000.0 / frames.max(1) as f64))
        .collect();
    let t = &stats.track;
    let valid = setup.rectifier.valid_rois();
    let roi_json = |r: &Roi| json!([r.x, r.y, r.w, r.h]);
    let summary = json!({
        "haul": setup.haul.dir.display().to_string(),
        "frames": frames,
        "width": setup.width,
        "height": setup.height,
        "fish_count": w.fish.len(),
        "fish_measured": n,
        "length_mm": {
            "count": n,
            "mean": mean,
            "sd": sd,
            "median": median,
            "min": lengths.first(),
            "max": lengths.last(),
        },
        "rows": {
            "tracks": w.tracks,
            "detections": w.detections,
            "stereo": w.stereo_rows,
        },
        "counts": {
            "left_objects": stats.left_objects,
            "right_objects": stats.right_objects,
            "stereo_pairs": stats.pairs,
            "stereo_pairs_searched": stats.pairs_searched,
            "stereo_sad_ops": stats.pair_sad_ops,
            "pairs_measured": stats.measured,
            "length_failed": stats.length_failed,
            "length_withheld": stats.length_withheld,
            "tracks_born": t.targets_born,
            "tracks_closed": t.tracks_closed,
            "duplicate_tracks": w.duplicates,
            "unconfirmed_tracks": w.unconfirmed,
            "sliver_tracks": w.slivers,
            "fish_length_inconsistent": w.inconsistent,
        },
        "dropped": {
            "left_objects": stats.left_objects_dropped,
            "right_objects": stats.right_objects_dropped,
            "observations": stats.observations_dropped,
            "tracker_observations": t.obs_dropped,
            "tracker_invalid_observations": t.obs_invalid,
            "targets": t.targets_dropped,
            "trellis_nodes": t.nodes_dropped,
            "path_steps": t.path_steps_dropped,
            "length_accumulators": stats.accumulators_dropped,
            "track_lengths": stats.lengths_dropped,
            "history_misses": stats.history_misses,
        },
        "timings_ms_per_frame": per_frame,
        "timings_total_s": total,
        "memory": {
            "pipeline_bytes": std::mem::size_of::<DefaultPipeline>(),
            "workspace_bytes": DefaultPipeline::workspace_size(setup.width as usize, setup.height as usize),
        },
        "params": setup.params,
        "track_overrides": setup.track,
        "fps": setup.fps,
        "crossing_width_px": track.crossing_width,
        "max_lost": track.max_lost,
        "column_offsets": setup.columns.iter().map(|c| serde_json::json!({
            "rms": c.as_ref().map(|c| c.rms),
            "applied": c.as_ref().is_some_and(|c| c.applied.is_some()),
        })).collect::<Vec<_>>(),
        "photometric": {
            "frames_mapped": stats.photometric_mapped,
            "frames_estimated": stats.photometric_estimated,
            "gain_median": gain_median,
            "offset_median": offset_median,
        },
        "rectification": {
            "alpha": setup.rectifier.alpha,
            "canvas": setup.rectifier.rect.outer.is_some(),
            "focal_px": setup.rectifier.rect.p1[(0, 0)],
            "valid_left": roi_json(&valid[0]),
            "valid_right": roi_json(&valid[1]),
        },
    });
    write_json(&out.join("summary.json"), &summary)
}

/// `fishtrack track HAUL... --out OUT`: one haul into OUT, several into
/// `OUT/<haul name>/` each plus `OUT/survey.csv` ([`crate::survey`]).
pub fn run(hauls: &[PathBuf], out: &Path, opts: &TrackOptions) -> Result<()> {
    if let Some(t) = &opts.tracker {
        parse_tracker(t)?;
    }
    crate::survey::run(hauls, out, opts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(id: u32, frame: u32, w: f64, h: f64, conf: f64) -> TrackRow {
        TrackRow {
            frame,
            id,
            bbox: [0.0, 100.0, w, h],
            conf,
            xyz: None,
        }
    }

    #[test]
    fn a_track_never_showing_a_fish_sized_box_is_a_sliver() {
        let amin = 2000.0;
        let rows = [
            // a sliver at the raw edge, seen once
            row(1, 3, 37.0, 40.0, 1.0),
            // small when it entered, fish-sized later: a fish
            row(2, 3, 30.0, 60.0, 1.0),
            row(2, 4, 200.0, 60.0, 1.0),
            // fish-sized only where predicted (conf 0.5): never observed so
            row(3, 5, 40.0, 40.0, 1.0),
            row(3, 6, 300.0, 80.0, 0.5),
            // exactly θ_A^L: may hold a fish
            row(4, 7, 40.0, 50.0, 1.0),
        ];
        let s = sliver_tracks(&rows, amin);
        assert_eq!(s.into_iter().collect::<Vec<_>>(), vec![1, 3]);
        assert!(sliver_tracks(&rows, 1.0).is_empty());
    }
}
