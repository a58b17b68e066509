//! `fishtrack bench HAUL [--json]`: where the time goes (issue 8).
//!
//! Every figure is the median over repeated runs (`--repeats`, default 3)
//! of each run's mean per pair, on the haul's frames (`--frames N`: the first N pairs):
//! - `read`, `rectify`: decoding both files, remapping both frames (host;
//!   both sides in parallel), per pair;
//! - `mesh_removal` (Section V.A), `coarse` (Section III.A as configured:
//!   by default the 4 × 4 box mean, its 5 × 5 gradient, the median/MAD
//!   hysteresis and the labels; at `coarse_scale` 1 the 7 × 7 gradient,
//!   global threshold and streaming labels; plus the frame's noise
//!   estimate): the core's primitives ([`fishtrack_core::morph`],
//!   [`fishtrack_core::lowres`], [`fishtrack_core::label`]) run on both
//!   rectified frames of a pair as `segment::coarse` runs them;
//! - `segmentation`: both frames' [`Stage::SegmentLeft`] +
//!   [`Stage::SegmentRight`] inside the pipeline, and `local_segmentation`
//!   = segmentation − mesh removal − coarse (the per-region work, III.A–D);
//! - `stereo` (IV.A–B pairing), `length` (IV.D), `tracking` (IV.C): the
//!   pipeline's own stage ends;
//! - `core_pairs_per_s`: [`DefaultPipeline::process_frame`] over every pair
//!   with the rectified frames already in memory, one thread;
//! - `end_to_end_pairs_per_s`: read → rectify → pipeline as `fishtrack
//!   track` runs it ([`crate::frame_source`], decoding and rectification
//!   overlapping the core), outputs not written;
//! - `peak_rss_bytes` (`VmHWM` of `/proc/self/status`), `pipeline_state_bytes`
//!   (`size_of::<DefaultPipeline>()`, limit 512 KiB) and `workspace_bytes`.

use crate::stats::median;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use serde_json::{json, Value};

use fishtrack_core::hist::add_row_256;
use fishtrack_core::label::{label_components, StreamLabeler, RUN_WORDS, SLOT_WORDS};
use fishtrack_core::lowres::{box_mean16, gradient_disk_u16, low_size, median_mad_u16};
use fishtrack_core::morph::{disk_scratch_len, gradient_disk, remove_mesh, Disk};
use fishtrack_core::pipeline::{DefaultPipeline, PipelineEvent, Stage};
use fishtrack_core::segment::coarse::{gradient_threshold, hysteresis_thresholds, COARSE_LOW_DISK};
use fishtrack_core::ImageView;

use crate::error::InputError;
use crate::frame_source::{for_each_rectified, rectify_one};
use crate::track_cmd::{new_pipeline, prepare, views, Setup, TrackOptions};

/// Limit on `size_of::<DefaultPipeline>()` (issue 8): 512 KiB.
pub const STATE_LIMIT_BYTES: usize = 512 * 1024;

/// Stage keys of `stage_ms_per_pair`, in pipeline order.
pub const STAGES: [&str; 10] = [
    "read",
    "rectify",
    "mesh_removal",
    "coarse",
    "local_segmentation",
    "segmentation",
    "stereo",
    "length",
    "tracking",
    "core_total",
];

/// Options of `fishtrack bench`.
#[derive(Debug, Clone, Copy)]
pub struct BenchOptions {
    /// Repeated runs (medians are reported).
    pub repeats: usize,
    /// Only the first N pairs.
    pub frames: Option<usize>,
    /// `--rect-alpha` (the default scaling when absent).
    pub rect_alpha: Option<crate::rectify::Scaling>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            repeats: 3,
            frames: None,
            rect_alpha: None,
        }
    }
}

/// What `bench` measured.
#[derive(Debug, Clone)]
pub struct BenchReport {
    /// The haul.
    pub haul: String,
    /// Frame width.
    pub width: u32,
    /// Frame height.
    pub height: u32,
    /// Pairs per run.
    pub pairs: usize,
    /// Runs.
    pub repeats: usize,
    /// Median milliseconds per pair, by stage ([`STAGES`]).
    pub stage_ms: BTreeMap<&'static str, f64>,
    /// Core pairs per second, one thread, frames in memory.
    pub core_pairs_per_s: f64,
    /// End-to-end pairs per second (read, rectify, pipeline).
    pub end_to_end_pairs_per_s: f64,
    /// Peak resident memory of this process, bytes (`None` off Linux).
    pub peak_rss_bytes: Option<u64>,
    /// `size_of::<DefaultPipeline>()`.
    pub pipeline_state_bytes: usize,
    /// Segmentation workspace bytes.
    pub workspace_bytes: usize,
    /// Worker threads of the host's pool.
    pub threads: usize,
}

/// The median over runs of each run's mean: `v` holds `n` per-pair
/// samples per run, run after run. A per-pair median would hide stages
/// that only some frames need (stereo, length and tracking are zero on
/// frames without fish), so each run is summarised by its mean first.
fn median_of_run_means(v: &[f64], n: usize) -> f64 {
    let mut means: Vec<f64> = v
        .chunks(n.max(1))
        .map(|c| c.iter().sum::<f64>() / c.len() as f64)
        .collect();
    median(&mut means)
}

/// `VmHWM` of `/proc/self/status` in bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Scratch for timing the coarse primitives on their own.
struct CoarseBufs {
    filtered: Vec<u8>,
    grad: Vec<u8>,
    disk: Vec<u8>,
    slots: Vec<[u64; SLOT_WORDS]>,
    free: Vec<u32>,
    prev: Vec<[u32; RUN_WORDS]>,
    cur: Vec<[u32; RUN_WORDS]>,
    low: Vec<u16>,
    low_grad: Vec<u16>,
    low_labels: Vec<i32>,
    low_mask: Vec<u8>,
}

impl CoarseBufs {
    fn new(w: usize, h: usize, radius: usize) -> Self {
        let (t, r) = (StreamLabeler::table_len(w), StreamLabeler::runs_len(w));
        CoarseBufs {
            filtered: vec![0; w * h],
            grad: vec![0; w * h],
            disk: vec![0; disk_scratch_len(w, radius)],
            slots: vec![[0; SLOT_WORDS]; t],
            free: vec![0; t],
            prev: vec![[0; RUN_WORDS]; r],
            cur: vec![[0; RUN_WORDS]; r],
            low: Vec::new(),
            low_grad: Vec::new(),
            low_labels: Vec::new(),
            low_mask: Vec::new(),
        }
    }

    /// Seconds of (mesh removal, gradient + threshold + labels) on `img`;
    /// the component count keeps the work observable.
    fn time(&mut self, img: ImageView<'_>, setup: &Setup) -> Result<(f64, f64, usize)> {
        let (w, h) = (img.width(), img.height());
        let p = &setup.params;
        let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("bench coarse pass: {e}");
        let t0 = Instant::now();
        let len = p.mesh_line_len as usize;
        if len >= 3 {
            remove_mesh(img, len, &mut self.grad, &mut self.filtered).map_err(|e| err(&e))?;
        } else {
            for (y, o) in self.filtered.chunks_exact_mut(w).take(h).enumerate() {
                o.copy_from_slice(img.row(y));
            }
        }
        let mesh = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        std::hint::black_box(fishtrack_core::noise::noise_sigma16(img));
        let mut comps = 0usize;
        if p.coarse_scale > 1 {
            // the mesh-free frame, lent out while the other buffers are used
            let filtered = std::mem::take(&mut self.filtered);
            let fv = ImageView::packed(&filtered, w, h).map_err(|e| err(&e))?;
            let r = self.low_res(fv, setup);
            self.filtered = filtered;
            return Ok((mesh, t1.elapsed().as_secs_f64(), r?));
        }
        let disk = Disk::opencv_ellipse(p.disk_size);
        let fv = ImageView::packed(&self.filtered, w, h).map_err(|e| err(&e))?;
        gradient_disk(fv, &disk, &mut self.grad, &mut self.disk).map_err(|e| err(&e))?;
        let mut hist = [0u32; 256];
        for row in self.grad.chunks_exact(w).take(h) {
            add_row_256(&mut hist, row);
        }
        let t = gradient_threshold(&hist);
        let mut labeler = StreamLabeler::new(
            w,
            &mut self.slots,
            &mut self.free,
            &mut self.prev,
            &mut self.cur,
        )
        .map_err(|e| err(&e))?;
        for row in self.grad.chunks_exact(w).take(h) {
            labeler.push_row_above(row, t, |_| comps += 1);
        }
        labeler.finish(|_| comps += 1);
        Ok((mesh, t1.elapsed().as_secs_f64(), comps))
    }
}

impl CoarseBufs {
    /// The reduced-resolution coarse pass as `segment::coarse` runs it
    /// (downsample, 5 × 5 gradient, median/MAD hysteresis, labels, the
    /// kept components' moments); returns the kept components.
    fn low_res(&mut self, fv: ImageView<'_>, setup: &Setup) -> Result<usize> {
        let err = |e: &dyn std::fmt::Debug| anyhow::anyhow!("bench coarse pass: {e:?}");
        let f = setup.params.coarse_scale as usize;
        let (lw, lh) = low_size(fv.width(), fv.height(), f);
        let nl = lw * lh;
        self.low.resize(nl, 0);
        self.low_grad.resize(nl, 0);
        self.low_labels.resize(nl, 0);
        self.low_mask.resize(nl, 0);
        box_mean16(fv, f, &mut self.low).map_err(|e| err(&e))?;
        let disk = Disk::opencv_ellipse(COARSE_LOW_DISK);
        gradient_disk_u16(&self.low, lw, lh, &disk, &mut self.low_grad).map_err(|e| err(&e))?;
        // the core's 1024-bin median/MAD histograms
        let (mut hist, mut dev) = (vec![0u32; 1024], vec![0u32; 1024]);
        let (med, mad) = median_mad_u16(&self.low_grad, &mut hist, &mut dev);
        let (t_low, t_high) = hysteresis_thresholds(med, mad);
        for (m, &g) in self.low_mask.iter_mut().zip(&self.low_grad) {
            *m = if g > t_low { 255 } else { 0 };
        }
        let min_low = ((setup.params.area_min / 4).max(1) as usize).div_ceil(f * f) as u32;
        let mv = ImageView::packed(&self.low_mask, lw, lh).map_err(|e| err(&e))?;
        let n =
            label_components(mv, &mut self.low_labels, |a| a >= min_low).map_err(|e| err(&e))?;
        let mut seeded = vec![false; n as usize];
        for (&l, &g) in self.low_labels.iter().zip(&self.low_grad) {
            if l > 0 && g > t_high {
                if let Some(s) = seeded.get_mut(l as usize - 1) {
                    *s = true;
                }
            }
        }
        for (m, &l) in self.low_mask.iter_mut().zip(&self.low_labels) {
            let keep = l > 0 && seeded.get(l as usize - 1).copied().unwrap_or(false);
            *m = if keep { 255 } else { 0 };
        }
        let mut labeler = StreamLabeler::new(
            lw,
            &mut self.slots,
            &mut self.free,
            &mut self.prev,
            &mut self.cur,
        )
        .map_err(|e| err(&e))?;
        let mut comps = 0usize;
        for row in self.low_mask.chunks_exact(lw.max(1)).take(lh) {
            labeler.push_row_above(row, 0, |_| comps += 1);
        }
        labeler.finish(|_| comps += 1);
        Ok(comps)
    }
}

/// Runs the benchmark on `dir`.
pub fn bench(dir: &Path, opts: &BenchOptions) -> Result<BenchReport> {
    let setup = prepare(
        dir,
        &TrackOptions {
            rect_alpha: opts.rect_alpha,
            ..TrackOptions::default()
        },
    )?;
    let n = opts
        .frames
        .unwrap_or(usize::MAX)
        .min(setup.haul.frames.len());
    if n == 0 {
        return Err(InputError::file(dir, "--frames 0: nothing to measure").into());
    }
    let pairs = &setup.haul.frames[..n];
    let repeats = opts.repeats.max(1);
    let (w, h) = (setup.width as usize, setup.height as usize);
    let mut samples: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    let mut push = |k: &'static str, s: f64| samples.entry(k).or_default().push(s * 1e3);

    // progress on a terminal: four passes over the pairs per run
    let bar = crate::progress::bar((4 * repeats * n) as u64, "bench", "pairs");
    // 1. read + rectify, sequential per pair (both sides in parallel)
    let mut frames = Vec::with_capacity(n);
    for rep in 0..repeats {
        for pair in pairs {
            let rp = rectify_one(&setup, pair)?;
            bar.inc(1);
            push("read", rp.read_s);
            push("rectify", rp.rectify_s);
            if rep == 0 {
                frames.push((rp.left, rp.right));
            }
        }
    }
    // 2. core, frames in memory, one thread
    let mut ws = vec![0u8; DefaultPipeline::workspace_size(w, h)];
    let mut core_rates = Vec::new();
    let mut seg = vec![0.0f64; n];
    for _ in 0..repeats {
        let mut pipe = new_pipeline(&setup)?;
        let started = Instant::now();
        for (i, (pair, (l, r))) in pairs.iter().zip(&frames).enumerate() {
            let (lv, rv) = views(l, r)?;
            let mut st = [0.0f64; 4]; // segmentation, stereo, length, tracking
            let t_pair = Instant::now();
            let mut last = Instant::now();
            pipe.process_frame(pair.index, lv, rv, &mut ws, &mut |e| {
                if let PipelineEvent::StageDone { stage, .. } = e {
                    let k = match stage {
                        Stage::SegmentLeft | Stage::SegmentRight => 0,
                        Stage::Pair => 1,
                        Stage::Length => 2,
                        Stage::Track => 3,
                    };
                    st[k] += last.elapsed().as_secs_f64();
                    last = Instant::now();
                }
            })
            .map_err(|e| {
                InputError::file(&pair.left, format!("frame {}: pipeline: {e}", pair.index))
            })?;
            push("core_total", t_pair.elapsed().as_secs_f64());
            bar.inc(1);
            push("segmentation", st[0]);
            push("stereo", st[1]);
            push("length", st[2]);
            push("tracking", st[3]);
            seg[i] = st[0];
        }
        core_rates.push(n as f64 / started.elapsed().as_secs_f64());
    }
    // 3. the coarse primitives on their own; local = segmentation − both
    let radius = Disk::opencv_ellipse(setup.params.disk_size).radius;
    let mut bufs = CoarseBufs::new(w, h, radius);
    for _ in 0..repeats {
        for (i, (l, r)) in frames.iter().enumerate() {
            let (lv, rv) = views(l, r)?;
            let (m1, c1, _) = bufs.time(lv, &setup)?;
            let (m2, c2, _) = bufs.time(rv, &setup)?;
            bar.inc(1);
            push("mesh_removal", m1 + m2);
            push("coarse", c1 + c2);
            push(
                "local_segmentation",
                (seg.get(i).copied().unwrap_or(0.0) - (m1 + m2 + c1 + c2)).max(0.0),
            );
        }
    }
    drop(frames);
    // 4. end to end, read and rectify overlapping the core
    let mut e2e_rates = Vec::new();
    for _ in 0..repeats {
        let mut pipe = new_pipeline(&setup)?;
        let started = Instant::now();
        for_each_rectified(&setup, pairs, |rp| {
            let (lv, rv) = views(&rp.left, &rp.right)?;
            pipe.process_frame(rp.pair.index, lv, rv, &mut ws, &mut |_| {})
                .map_err(|e| {
                    InputError::file(
                        &rp.pair.left,
                        format!("frame {}: pipeline: {e}", rp.pair.index),
                    )
                })?;
            bar.inc(1);
            Ok(())
        })?;
        e2e_rates.push(n as f64 / started.elapsed().as_secs_f64());
    }
    bar.finish_and_clear();
    let stage_ms = STAGES
        .iter()
        .map(|&k| {
            (
                k,
                median_of_run_means(samples.get(k).map_or(&[][..], |v| &v[..]), n),
            )
        })
        .collect();
    Ok(BenchReport {
        haul: dir.display().to_string(),
        width: setup.width,
        height: setup.height,
        pairs: n,
        repeats,
        stage_ms,
        core_pairs_per_s: median(&mut core_rates),
        end_to_end_pairs_per_s: median(&mut e2e_rates),
        peak_rss_bytes: peak_rss_bytes(),
        pipeline_state_bytes: std::mem::size_of::<DefaultPipeline>(),
        workspace_bytes: ws.len(),
        threads: rayon::current_num_threads(),
    })
}

impl BenchReport {
    /// The JSON document (keys documented in README, "Performance").
    pub fn json(&self) -> Value {
        json!({
            "haul": self.haul,
            "width": self.width,
            "height": self.height,
            "pairs": self.pairs,
            "repeats": self.repeats,
            "threads": self.threads,
            "stage_ms_per_pair": self.stage_ms,
            "core_pairs_per_s": self.core_pairs_per_s,
            "end_to_end_pairs_per_s": self.end_to_end_pairs_per_s,
            "peak_rss_bytes": self.peak_rss_bytes,
            "pipeline_state_bytes": self.pipeline_state_bytes,
            "pipeline_state_limit_bytes": STATE_LIMIT_BYTES,
            "workspace_bytes": self.workspace_bytes,
        })
    }

    /// A human-readable table.
    pub fn table(&self) -> String {
        let mut s = format!(
            "fishtrack bench: {} ({}x{}, {} pairs, median of {} runs, {} host threads)\n\n",
            self.haul, self.width, self.height, self.pairs, self.repeats, self.threads
        );
        s += &format!("{:<22}{:>12}\n", "stage", "ms/pair");
        for k in STAGES {
            s += &format!(
                "{k:<22}{:>12.2}\n",
                self.stage_ms.get(k).copied().unwrap_or(0.0)
            );
        }
        s += &format!(
            "\ncore pairs/s (1 thread, frames in memory)  {:>10.1}\n",
            self.core_pairs_per_s
        );
        s += &format!(
            "end-to-end pairs/s (read+rectify+core)     {:>10.1}\n",
            self.end_to_end_pairs_per_s
        );
        let rss = self
            .peak_rss_bytes
            .map(|b| format!("{:.1} MiB", b as f64 / (1 << 20) as f64))
            .unwrap_or_else(|| "unknown".into());
        s += &format!("peak RSS                                   {rss:>10}\n");
        s += &format!(
            "pipeline state (size_of)                   {:>10} B (limit {} B{})\n",
            self.pipeline_state_bytes,
            STATE_LIMIT_BYTES,
            if self.pipeline_state_bytes <= STATE_LIMIT_BYTES {
                ""
            } else {
                ", OVER"
            }
        );
        s += &format!(
            "segmentation workspace                     {:>10} B\n",
            self.workspace_bytes
        );
        s
    }
}

/// `fishtrack bench`.
pub fn run(dir: &Path, json: bool, opts: &BenchOptions) -> Result<()> {
    let r = bench(dir, opts)?;
    if json {
        crate::outln!("{}", r.json())?;
    } else {
        crate::out!("{}", r.table())?;
    }
    Ok(())
}
