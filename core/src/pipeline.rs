//! The whole device pipeline of one stereo frame pair (paper Fig. 6, the
//! data flow of the system):
//!
//! ```text
//! rectified left ─► segment (III) ─► left objects ─┐
//! rectified right ─► segment (III) ─► right objects ┴► stereo pairing (IV.A)
//!     [─► right view mapped to the left's grey levels, pairing again]
//!     ─► 3-D length per pair (IV.D) ─► observations ─► matching cost (IV.B)
//!     + multi-target Viterbi data association (IV.C) ─► tracks ─► fish
//!        (count + per-track length: median of the wholly-inside frames that
//!         agree, `LengthConfig::track_agreement`)
//! ```
//!
//! Data flows one way; [`Pipeline::process_frame`] runs every stage on one
//! frame and reports [`PipelineEvent`]s to a sink: every left object of the
//! frame with its stereo result, every committed track frame (up to the
//! trellis depth `D` frames late, see [`crate::track`]) with its box and 3-D
//! centroid, every closed track with its length estimate (Section IV.D.2:
//! the median of the per-frame lengths of the frames where the fish is
//! wholly inside both views), the end of each stage (so a host can time the
//! stages without the core owning a clock) and the frame's counters.
//! [`Pipeline::finish`] closes the remaining tracks at the end of a haul.
//!
//! The bracketed step is beyond the paper ([`crate::photometric`],
//! `Params::photometric`): when the stereo pairs of the recent frames say
//! the two cameras record the fish at different grey levels, the right
//! frame is mapped through a look-up table into the workspace (free once
//! both views are segmented) and the pairing and the lengths use the
//! mapped view; the two views' water levels give each frame's flash
//! factor, so a flash that lights one view more than the other is mapped
//! too.
//!
//! # Memory
//! Everything is inline: `Pipeline<N, R, T, D, K, H, Q, F>` holds the left
//! and right [`Objects<N, R>`], the frame's pairs, lengths and
//! observations, the [`Tracker<T, D, K, H, N>`], a ring of the last `Q`
//! frames' per-observation results (committed track frames arrive up to `D`
//! frames late, so `Q > D` is required), a table of `T` per-track
//! [`LengthAccumulator<F>`]s keyed by track id, and the photometric pool
//! ([`photometric::POOL`] samples and as many frames' level ratios). The
//! segmentation scratch is the caller's `ws` of [`Pipeline::workspace_size`] bytes. Capacity
//! overflow anywhere is counted in [`PipelineStats`], never fatal.
//! `size_of::<DefaultPipeline>()` is checked to stay ≤ 512 KiB.

use crate::error::ImageError;
use crate::geometry::StereoGeometry;
use crate::image::{ImageView, Roi};
use crate::length::{
    measure_length, wholly_inside_valid, FishLength, LengthAccumulator, LengthConfig,
    LengthEstimate,
};
use crate::object::{Object, Objects, OrientedBox};
use crate::params::Params;
use crate::photometric::{self, Photometric};
use crate::segment::{segment_frame, SegmentError, RECOMMENDED_MAX_ROI_PIXELS};
use crate::stereo::{pair_objects, PairingLimits, StereoPair, StereoPairs};
use crate::track::{
    CameraView, CloseReason, Observation, TrackConfig, TrackError, TrackEvent, TrackStats, Tracker,
};

/// Refined disparity blocks per pair kept by the length stage.
pub const REFINE_BLOCKS: usize = 1024;

/// The default pipeline: 64 objects and 16384 mask runs per view, the
/// [`crate::track::DefaultTracker`] capacities, an 18-frame history and 32
/// lengths per track.
pub type DefaultPipeline = Pipeline<64, 16384, 32, 16, 8, 32, 18, 32>;

/// Why a frame could not be processed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum PipelineError {
    /// Segmentation refused the frame (workspace, size, parameters).
    Segment(SegmentError),
    /// The two frames are unusable together.
    Image(ImageError),
    /// The tracker refused the frame or its configuration.
    Track(TrackError),
    /// The history depth `Q` must exceed the trellis depth `D`.
    History,
}

impl core::fmt::Display for PipelineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PipelineError::Segment(e) => write!(f, "{e}"),
            PipelineError::Image(e) => write!(f, "stereo: {e}"),
            PipelineError::Track(e) => write!(f, "tracking: {e}"),
            PipelineError::History => {
                f.write_str("pipeline history must be deeper than the trellis")
            }
        }
    }
}

impl core::error::Error for PipelineError {}

/// Everything fixed for a haul.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PipelineConfig {
    /// Table I parameters.
    pub params: Params,
    /// Rectified stereo geometry.
    pub geometry: StereoGeometry,
    /// Tracking options.
    pub track: TrackConfig,
    /// Stereo pairing gate.
    pub pairing: PairingLimits,
    /// Length stage options.
    pub length: LengthConfig,
    /// Border margin (pixels) for the wholly-inside test of a length.
    pub inside_margin: u32,
    /// Left and right rectangles of the rectified frames where every pixel
    /// has a raw source (OpenCV's `validPixROI1/2`; the whole frame by
    /// default, as at `alpha = 0`; the host sets them from
    /// `Rectifier::valid_rois`, its default alpha being 0.25): the
    /// wholly-inside test of a length
    /// keeps `inside_margin` from their edges ([`wholly_inside_valid`]).
    pub valid: [Roi; 2],
}

impl PipelineConfig {
    /// Defaults for `params` and `geometry` on `width × height` rectified frames.
    pub fn new(params: Params, geometry: StereoGeometry, width: u32, height: u32) -> Self {
        PipelineConfig {
            params,
            geometry,
            track: TrackConfig::for_frame(width, height),
            pairing: PairingLimits::default(),
            length: LengthConfig::default(),
            inside_margin: 2,
            valid: [Roi::new(0, 0, width, height); 2],
        }
    }
}

/// A pipeline stage, reported when it ends ([`PipelineEvent::StageDone`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Stage {
    /// Segmentation of the left frame.
    SegmentLeft,
    /// Segmentation of the right frame.
    SegmentRight,
    /// Stereo pairing.
    Pair,
    /// Length measurement of every pair.
    Length,
    /// Tracking (data association and events).
    Track,
}

/// The stereo result of one left object.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StereoInfo {
    /// Index of the right object.
    pub right: u16,
    /// The right object's upright box, rectified pixels.
    pub right_box: Roi,
    /// The pair as stereo pairing found it.
    pub pair: StereoPair,
    /// The length measurement, if it succeeded (its length is usable only
    /// when [`FishLength::consistent`]; see [`StereoInfo::length_mm`]).
    pub length: Option<FishLength>,
    /// Both boxes keep the margin from every border (length usable).
    pub wholly_inside: bool,
}

impl StereoInfo {
    /// The usable length, mm: measured and consistent between the views.
    pub fn length_mm(&self) -> Option<f32> {
        self.length.filter(|l| l.consistent).map(|l| l.length_mm)
    }
}

/// Per-frame counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameCounts {
    /// Left objects.
    pub left_objects: u32,
    /// Right objects.
    pub right_objects: u32,
    /// Stereo pairs.
    pub pairs: u32,
    /// Pairs with a length.
    pub measured: u32,
    /// Live tracks after the frame.
    pub live_tracks: u32,
}

/// What the pipeline reports.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PipelineEvent {
    /// A stage of the current frame ended.
    StageDone {
        /// The frame.
        frame: u32,
        /// The stage.
        stage: Stage,
    },
    /// One left object of the frame (all rectified pixels).
    Object {
        /// The frame.
        frame: u32,
        /// Index among the frame's left objects (= observation index).
        index: u16,
        /// Upright box.
        bbox: Roi,
        /// Oriented box (its width `2·half_w` is the oriented length, px).
        obb: OrientedBox,
        /// Mask area, pixels.
        area: u32,
        /// Stereo result, if paired.
        stereo: Option<StereoInfo>,
    },
    /// One committed frame of a track.
    TrackFrame {
        /// Track id.
        track: u32,
        /// The frame.
        frame: u32,
        /// Observation (= left object) index, `None` when predicted.
        obs: Option<u16>,
        /// Upright left box, rectified pixels. A lost (predicted) frame is
        /// reported when the track's next observation arrives, with the box
        /// interpolated between the observations before and after it
        /// (centroid, offsets and size linear in time); lost frames with no
        /// later observation (beyond [`MAX_PENDING`], or at a close) get
        /// the last observed box moved to the predicted position.
        bbox: Roi,
        /// 3-D centroid, mm, rectified left camera frame, if known.
        centre: Option<[f32; 3]>,
    },
    /// A track ended; all its frames were reported before.
    TrackClosed {
        /// Track id.
        track: u32,
        /// Why.
        reason: CloseReason,
        /// First frame with an observation.
        first_frame: u32,
        /// Last frame with an observation.
        last_frame: u32,
        /// Committed frames reported for it (observed or predicted).
        frames: u32,
        /// Frames with an observation.
        hits: u32,
        /// Length estimate over the wholly-inside measured frames that
        /// agree ([`LengthAccumulator::estimate_agreeing`] with
        /// `LengthConfig::track_agreement`).
        length: LengthEstimate,
        /// Median range (distance of the 3-D centroid from the left camera), mm.
        range_mm: Option<f32>,
    },
    /// The frame is done.
    FrameDone {
        /// The frame.
        frame: u32,
        /// Its counters.
        counts: FrameCounts,
    },
}

/// Cumulative counters, capacity drops included.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PipelineStats {
    /// Frames processed.
    pub frames: u32,
    /// Left objects segmented.
    pub left_objects: u32,
    /// Right objects segmented.
    pub right_objects: u32,
    /// Left objects dropped by the `Objects` capacity.
    pub left_objects_dropped: u32,
    /// Right objects dropped by the `Objects` capacity.
    pub right_objects_dropped: u32,
    /// Stereo pairs.
    pub pairs: u32,
    /// Of those, pairs whose right object the epipolar search found
    /// ([`crate::epipolar`]).
    pub pairs_searched: u32,
    /// Absolute differences the pairing computed (object-height blocks,
    /// `d_o` and the epipolar search; [`crate::stereo::PairingStats::sad_ops`]).
    pub pair_sad_ops: u64,
    /// Pairs measured.
    pub measured: u32,
    /// Pairs whose length measurement failed.
    pub length_failed: u32,
    /// Lengths measured but withheld: the two views' masks disagree at an
    /// end ([`crate::length::FishLength::consistent`]).
    pub length_withheld: u32,
    /// Observations that did not fit the frame's `N`.
    pub observations_dropped: u32,
    /// Track frames whose frame had left the history ring (no box/length).
    pub history_misses: u32,
    /// Tracks not given a length accumulator (table of `T` full).
    pub accumulators_dropped: u32,
    /// Per-track lengths beyond `F` (ignored).
    pub lengths_dropped: u32,
    /// Frames whose right view was mapped to the left's grey levels before
    /// pairing and measuring ([`crate::photometric`]).
    pub photometric_mapped: u32,
    /// Frames whose pairs added samples to the photometric estimate.
    pub photometric_estimated: u32,
    /// The tracker's counters.
    pub track: TrackStats,
}

/// Per-observation result kept for late committed track frames.
#[derive(Debug, Clone, Copy, Default)]
struct ObsInfo {
    bbox: Roi,
    cx: f32,
    cy: f32,
    length_mm: Option<f32>,
    inside: bool,
    centre: Option<[f32; 3]>,
}

#[derive(Debug, Clone)]
struct FrameSlot<const N: usize> {
    frame: Option<u32>,
    obs: heapless::Vec<ObsInfo, N>,
}

#[derive(Debug, Clone)]
struct TrackAcc<const F: usize> {
    id: u32,
    lengths: LengthAccumulator<F>,
    ranges: LengthAccumulator<F>,
    frames: u32,
    /// The track's last observed frame.
    last: Option<LastObs>,
    /// Lost frames after `last`, held until the next observation so their
    /// boxes can be interpolated (see [`PipelineEvent::TrackFrame`]).
    pending: heapless::Vec<Pending, MAX_PENDING>,
}

/// Most lost frames a track holds back for interpolation; older ones are
/// reported with the predicted box (only when `max_lost` exceeds it).
pub const MAX_PENDING: usize = 8;

/// A track's last observation: frame, centroid and box relative to it.
#[derive(Debug, Clone, Copy)]
struct LastObs {
    frame: u32,
    cx: f32,
    cy: f32,
    dx: f32,
    dy: f32,
    w: u32,
    h: u32,
}

impl LastObs {
    fn of(frame: u32, o: &ObsInfo) -> Self {
        LastObs {
            frame,
            cx: o.cx,
            cy: o.cy,
            dx: o.bbox.x as f32 - o.cx,
            dy: o.bbox.y as f32 - o.cy,
            w: o.bbox.w,
            h: o.bbox.h,
        }
    }
}

/// A lost (predicted) frame waiting for the track's next observation.
#[derive(Debug, Clone, Copy)]
struct Pending {
    frame: u32,
    x: i16,
    y: i16,
}

/// The per-frame pipeline state (see the module documentation).
///
/// `N` objects per view (and observations per frame), `R` mask runs per
/// view, `T` live tracks, `D` trellis depth, `K` nodes per stage, `H` path
/// steps per track, `Q` frames of history (`Q > D`), `F` lengths per track.
#[derive(Debug, Clone)]
pub struct Pipeline<
    const N: usize,
    const R: usize,
    const T: usize,
    const D: usize,
    const K: usize,
    const H: usize,
    const Q: usize,
    const F: usize,
> {
    cfg: PipelineConfig,
    left: Objects<N, R>,
    right: Objects<N, R>,
    pairs: StereoPairs<N>,
    lengths: heapless::Vec<Option<FishLength>, N>,
    observations: heapless::Vec<Observation, N>,
    tracker: Tracker<T, D, K, H, N>,
    history: [FrameSlot<N>; Q],
    accs: heapless::Vec<TrackAcc<F>, T>,
    stats: PipelineStats,
    /// The photometric map of the last frame (the pool's, after the
    /// frame's flash factor).
    photometric: Photometric,
    /// The pool's map (identity until the pool gives one).
    photometric_rig: Photometric,
    /// The recent pairs' photometric samples.
    photometric_pool: photometric::Estimator,
}

fn view_of(o: &Object) -> CameraView {
    CameraView {
        cx: o.obb.cx,
        cy: o.obb.cy,
        bbox: o.bbox,
        area: o.area,
        hist: o.hist,
        angle: o.obb.angle,
        elongation: if o.obb.half_h > 0.0 {
            o.obb.half_w / o.obb.half_h
        } else {
            0.0
        },
    }
}

fn norm3(p: &[f32; 3]) -> f32 {
    micromath::F32(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        .sqrt()
        .0
}

impl<
        const N: usize,
        const R: usize,
        const T: usize,
        const D: usize,
        const K: usize,
        const H: usize,
        const Q: usize,
        const F: usize,
    > Pipeline<N, R, T, D, K, H, Q, F>
{
    /// Scratch bytes [`Pipeline::process_frame`] needs for `width × height`
    /// frames: the segmentation workspace with an ROI capacity of
    /// `min(width·height, RECOMMENDED_MAX_ROI_PIXELS)`.
    pub const fn workspace_size(width: usize, height: usize) -> usize {
        let px = width.saturating_mul(height);
        let roi = if px < RECOMMENDED_MAX_ROI_PIXELS {
            px
        } else {
            RECOMMENDED_MAX_ROI_PIXELS
        };
        crate::segment::workspace_size(width, height, roi)
    }

    /// A pipeline for a haul. Fails on invalid parameters, tracking
    /// configuration or capacities.
    pub fn new(cfg: PipelineConfig) -> Result<Self, PipelineError> {
        if Q <= D {
            return Err(PipelineError::History);
        }
        cfg.params
            .validate()
            .map_err(|e| PipelineError::Track(TrackError::Params(e)))?;
        let tracker = Tracker::new(cfg.track).map_err(PipelineError::Track)?;
        Ok(Pipeline {
            cfg,
            left: Objects::new(),
            right: Objects::new(),
            pairs: StereoPairs::default(),
            lengths: heapless::Vec::new(),
            observations: heapless::Vec::new(),
            tracker,
            history: core::array::from_fn(|_| FrameSlot {
                frame: None,
                obs: heapless::Vec::new(),
            }),
            accs: heapless::Vec::new(),
            stats: PipelineStats::default(),
            photometric: Photometric::IDENTITY,
            photometric_rig: Photometric::IDENTITY,
            photometric_pool: photometric::Estimator::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &PipelineConfig {
        &self.cfg
    }

    /// Cumulative counters.
    pub fn stats(&self) -> PipelineStats {
        let mut s = self.stats;
        s.track = self.tracker.stats();
        s
    }

    /// The last frame's left objects.
    pub fn left_objects(&self) -> &Objects<N, R> {
        &self.left
    }

    /// The last frame's right objects.
    pub fn right_objects(&self) -> &Objects<N, R> {
        &self.right
    }

    /// The photometric map of the last frame's right view to its left
    /// ([`crate::photometric`]; applied only when it is not within the
    /// tolerance of the identity).
    pub fn photometric(&self) -> Photometric {
        self.photometric
    }

    /// The last frame's stereo pairs.
    pub fn pairs(&self) -> &StereoPairs<N> {
        &self.pairs
    }

    /// The last frame's lengths, one per pair (same order).
    pub fn lengths(&self) -> &[Option<FishLength>] {
        &self.lengths
    }

    /// The last frame's observations, one per left object (same order).
    pub fn observations(&self) -> &[Observation] {
        &self.observations
    }

    /// Stereo pairs of this frame's objects on the views `left`, `right`.
    fn pair(
        &self,
        left: &ImageView<'_>,
        right: &ImageView<'_>,
    ) -> Result<StereoPairs<N>, PipelineError> {
        pair_objects(
            left,
            right,
            &self.left,
            &self.right,
            &self.cfg.geometry,
            &self.cfg.pairing,
        )
        .map_err(PipelineError::Image)
    }

    /// Runs every stage on one rectified frame pair (see the module
    /// documentation). `frame` must increase from call to call.
    pub fn process_frame(
        &mut self,
        frame: u32,
        left: ImageView<'_>,
        right: ImageView<'_>,
        ws: &mut [u8],
        sink: &mut impl FnMut(&PipelineEvent),
    ) -> Result<(), PipelineError> {
        if left.width() != right.width() || left.height() != right.height() {
            return Err(PipelineError::Image(ImageError::SizeMismatch));
        }
        let params = self.cfg.params;
        let stage = |sink: &mut dyn FnMut(&PipelineEvent), stage| {
            sink(&PipelineEvent::StageDone { frame, stage })
        };
        segment_frame(left, &params, ws, &mut self.left).map_err(PipelineError::Segment)?;
        stage(sink, Stage::SegmentLeft);
        segment_frame(right, &params, ws, &mut self.right).map_err(PipelineError::Segment)?;
        stage(sink, Stage::SegmentRight);
        self.stats.frames = self.stats.frames.saturating_add(1);
        self.stats.left_objects = self
            .stats
            .left_objects
            .saturating_add(self.left.items.len() as u32);
        self.stats.right_objects = self
            .stats
            .right_objects
            .saturating_add(self.right.items.len() as u32);
        self.stats.left_objects_dropped = self
            .stats
            .left_objects_dropped
            .saturating_add(self.left.dropped);
        self.stats.right_objects_dropped = self
            .stats
            .right_objects_dropped
            .saturating_add(self.right.dropped);

        self.pairs = self.pair(&left, &right)?;
        // the cameras' grey levels matched, then the pairs again on the
        // mapped right view (the workspace is free after segmentation)
        let mut right = right;
        if params.photometric {
            let q = self.photometric_pool.add_levels(&left, &right);
            let added =
                self.photometric_pool
                    .add_frame(&left, &right, &self.left, &self.pairs.pairs, q);
            if added > 0 {
                self.stats.photometric_estimated =
                    self.stats.photometric_estimated.saturating_add(1);
            }
            if let Some(m) = self.photometric_pool.map() {
                self.photometric_rig = m;
            }
            self.photometric = self.photometric_rig.after_flash(q);
            if !self.photometric.is_identity() {
                right = self
                    .photometric
                    .apply(&right, ws)
                    .map_err(PipelineError::Image)?;
                self.pairs = self.pair(&left, &right)?;
                self.stats.photometric_mapped = self.stats.photometric_mapped.saturating_add(1);
            }
        }
        // the left objects left unpaired, looked for in the right image
        if params.stereo_search {
            crate::epipolar::search_unpaired(
                &left,
                &right,
                &self.left,
                &mut self.right,
                &mut self.pairs,
                &self.cfg.geometry,
                &self.cfg.pairing,
            );
        }
        stage(sink, Stage::Pair);

        self.lengths.clear();
        for p in self.pairs.pairs.iter() {
            // a fish cut by a border has no length to measure (Section IV.D.2)
            let inside = match (
                self.left.items.get(p.left as usize),
                self.right.items.get(p.right as usize),
            ) {
                (Some(lo), Some(ro)) => {
                    wholly_inside_valid(&lo.bbox, &ro.bbox, &self.cfg.valid, self.cfg.inside_margin)
                }
                _ => false,
            };
            if !inside {
                let _ = self.lengths.push(None);
                continue;
            }
            let l = measure_length::<N, R, REFINE_BLOCKS>(
                &left,
                &right,
                &self.left,
                &self.right,
                p,
                &self.cfg.geometry,
                &params,
                &self.cfg.length,
            );
            let l = match l {
                Ok(v) => {
                    if !v.consistent {
                        self.stats.length_withheld = self.stats.length_withheld.saturating_add(1);
                    }
                    Some(v)
                }
                Err(_) => {
                    self.stats.length_failed = self.stats.length_failed.saturating_add(1);
                    None
                }
            };
            // one length per pair: the pairs fit N, so this push cannot fail
            let _ = self.lengths.push(l);
        }
        stage(sink, Stage::Length);

        // observations, the frame's history slot and the object events
        self.observations.clear();
        let slot_i = frame as usize % Q;
        let mut counts = FrameCounts {
            left_objects: self.left.items.len() as u32,
            // segmented ones (the search's are counted with the pairs)
            right_objects: (self.right.items.len() as u32)
                .saturating_sub(self.pairs.stats.searched),
            pairs: self.pairs.pairs.len() as u32,
            ..FrameCounts::default()
        };
        if let Some(slot) = self.history.get_mut(slot_i) {
            slot.frame = Some(frame);
            slot.obs.clear();
        }
        for (i, lo) in self.left.items.iter().enumerate() {
            let pi = self.pairs.pairs.iter().position(|p| p.left as usize == i);
            let stereo = pi.and_then(|k| {
                let p = *self.pairs.pairs.get(k)?;
                let ro = self.right.items.get(p.right as usize)?;
                let length = self.lengths.get(k).copied().flatten();
                Some(StereoInfo {
                    right: p.right,
                    right_box: ro.bbox,
                    pair: p,
                    length,
                    wholly_inside: wholly_inside_valid(
                        &lo.bbox,
                        &ro.bbox,
                        &self.cfg.valid,
                        self.cfg.inside_margin,
                    ),
                })
            });
            let depth = stereo.and_then(|s| self.cfg.geometry.depth(s.pair.d_o));
            let obs = Observation {
                left: view_of(lo),
                right: stereo
                    .and_then(|s| self.right.items.get(s.right as usize))
                    .map(view_of),
                depth_mm: depth,
                pair: i as u16,
            };
            if self.observations.push(obs).is_err() {
                self.stats.observations_dropped = self.stats.observations_dropped.saturating_add(1);
            }
            let length_mm = stereo.and_then(|s| s.length_mm());
            if length_mm.is_some() {
                counts.measured += 1;
            }
            let centre = stereo.and_then(|s| {
                s.length.map(|l| l.centre).or_else(|| {
                    self.cfg
                        .geometry
                        .triangulate(lo.obb.cx, lo.obb.cy, s.pair.d_o)
                        .map(|p| [p.x, p.y, p.z])
                })
            });
            let info = ObsInfo {
                bbox: lo.bbox,
                cx: lo.obb.cx,
                cy: lo.obb.cy,
                length_mm,
                inside: stereo.is_some_and(|s| s.wholly_inside),
                centre,
            };
            if let Some(slot) = self.history.get_mut(slot_i) {
                let _ = slot.obs.push(info);
            }
            sink(&PipelineEvent::Object {
                frame,
                index: i as u16,
                bbox: lo.bbox,
                obb: lo.obb,
                area: lo.area,
                stereo,
            });
        }
        self.stats.pairs = self.stats.pairs.saturating_add(counts.pairs);
        self.stats.pairs_searched = self
            .stats
            .pairs_searched
            .saturating_add(self.pairs.stats.searched);
        self.stats.pair_sad_ops = self
            .stats
            .pair_sad_ops
            .saturating_add(self.pairs.stats.sad_ops);
        self.stats.measured = self.stats.measured.saturating_add(counts.measured);

        let Pipeline {
            cfg,
            tracker,
            history,
            accs,
            stats,
            observations,
            ..
        } = self;
        let agree = cfg.length.track_agreement;
        let mut on_track = |e: &TrackEvent<'_>| handle(e, history, accs, stats, agree, sink);
        tracker
            .step(frame, observations, &params, &mut on_track)
            .map_err(PipelineError::Track)?;
        stage(sink, Stage::Track);
        counts.live_tracks = self.tracker.live_targets() as u32;
        sink(&PipelineEvent::FrameDone { frame, counts });
        Ok(())
    }

    /// Closes every live track at the end of a haul, reporting their
    /// remaining frames and their lengths. The pipeline can then start a
    /// new haul.
    pub fn finish(&mut self, sink: &mut impl FnMut(&PipelineEvent)) {
        let Pipeline {
            cfg,
            tracker,
            history,
            accs,
            stats,
            ..
        } = self;
        let agree = cfg.length.track_agreement;
        let mut on_track = |e: &TrackEvent<'_>| handle(e, history, accs, stats, agree, sink);
        tracker.finish(&mut on_track);
        self.accs.clear();
        for s in self.history.iter_mut() {
            s.frame = None;
            s.obs.clear();
        }
    }
}

/// Turns a tracker event into pipeline events, feeding the per-track
/// length accumulators.
fn handle<const N: usize, const Q: usize, const T: usize, const F: usize>(
    e: &TrackEvent<'_>,
    history: &[FrameSlot<N>; Q],
    accs: &mut heapless::Vec<TrackAcc<F>, T>,
    stats: &mut PipelineStats,
    agreement: f32,
    sink: &mut impl FnMut(&PipelineEvent),
) {
    match *e {
        TrackEvent::Frame { track, step } => {
            let slot = history
                .get(step.frame as usize % Q.max(1))
                .filter(|s| s.frame == Some(step.frame));
            if slot.is_none() && step.obs.is_some() {
                stats.history_misses = stats.history_misses.saturating_add(1);
            }
            let info = step
                .obs
                .and_then(|i| slot.and_then(|s| s.obs.get(i as usize)));
            let k = match accs.iter().position(|a| a.id == track) {
                Some(k) => Some(k),
                None => {
                    let fresh = TrackAcc {
                        id: track,
                        lengths: LengthAccumulator::new(),
                        ranges: LengthAccumulator::new(),
                        frames: 0,
                        last: None,
                        pending: heapless::Vec::new(),
                    };
                    if accs.push(fresh).is_ok() {
                        Some(accs.len() - 1)
                    } else {
                        stats.accumulators_dropped = stats.accumulators_dropped.saturating_add(1);
                        None
                    }
                }
            };
            let acc = k.and_then(|k| accs.get_mut(k));
            let Some(a) = acc else {
                // no accumulator (table full): report as is
                let bbox = match info {
                    Some(o) => o.bbox,
                    None => predicted_box(None, step.x, step.y),
                };
                sink(&PipelineEvent::TrackFrame {
                    track,
                    frame: step.frame,
                    obs: info.and(step.obs),
                    bbox,
                    centre: info.and_then(|o| o.centre),
                });
                return;
            };
            a.frames = a.frames.saturating_add(1);
            let Some(o) = info else {
                if a.last.is_some() {
                    // held until the next observation (interpolated box)
                    if a.pending.is_full() {
                        let oldest = a.pending.remove(0);
                        let bbox = predicted_box(a.last.as_ref(), oldest.x, oldest.y);
                        emit_lost(track, oldest.frame, bbox, sink);
                    }
                    let _ = a.pending.push(Pending {
                        frame: step.frame,
                        x: step.x,
                        y: step.y,
                    });
                } else {
                    emit_lost(track, step.frame, predicted_box(None, step.x, step.y), sink);
                }
                return;
            };
            let here = LastObs::of(step.frame, o);
            flush_pending(track, a, Some(&here), sink);
            let before = a.lengths.dropped;
            a.lengths.push(o.length_mm, o.inside);
            if a.lengths.dropped > before {
                stats.lengths_dropped = stats.lengths_dropped.saturating_add(1);
            }
            a.ranges.push(o.centre.as_ref().map(norm3), true);
            a.last = Some(here);
            sink(&PipelineEvent::TrackFrame {
                track,
                frame: step.frame,
                obs: step.obs,
                bbox: o.bbox,
                centre: o.centre,
            });
        }
        TrackEvent::Closed {
            track,
            reason,
            first_frame,
            last_frame,
            hits,
            ..
        } => {
            let k = accs.iter().position(|a| a.id == track);
            if let Some(a) = k.and_then(|k| accs.get_mut(k)) {
                // a track closes on an observation, so only frames beyond
                // it (none in practice) are left: the predicted boxes
                flush_pending(track, a, None, sink);
            }
            let (length, range_mm, frames) = match k.and_then(|k| accs.get(k)) {
                Some(a) => (
                    a.lengths.estimate_agreeing(agreement),
                    a.ranges.estimate().median_mm,
                    a.frames,
                ),
                None => (LengthEstimate::default(), None, 0),
            };
            if let Some(k) = k {
                accs.swap_remove(k);
            }
            sink(&PipelineEvent::TrackClosed {
                track,
                reason,
                first_frame,
                last_frame,
                frames,
                hits,
                length,
                range_mm,
            });
        }
    }
}

/// The last observed box of a track moved to the predicted centroid.
fn predicted_box(last: Option<&LastObs>, x: i16, y: i16) -> Roi {
    match last {
        Some(l) => box_at(x as f32 + l.dx, y as f32 + l.dy, l.w, l.h),
        None => Roi::new(x.max(0) as u32, y.max(0) as u32, 0, 0),
    }
}

/// A box at `(x0, y0)` (clamped to the frame's first row and column).
fn box_at(x0: f32, y0: f32, w: u32, h: u32) -> Roi {
    let c = |v: f32| if v > 0.0 { v as u32 } else { 0 };
    Roi::new(c(x0), c(y0), w, h)
}

/// The box of a lost frame `frame` between the observations `a` and `b`
/// (`a.frame < frame < b.frame`): centroid and box offsets and sizes
/// interpolated linearly in time. A fish crossing the view at about
/// constant velocity is nearer this than the prediction `x + v` made
/// before `b` was seen (seeds 1–30: lost-frame boxes on the fish at
/// IoU ≥ 0.4, 18 → 31 of 74).
fn interpolated_box(a: &LastObs, b: &LastObs, frame: u32) -> Roi {
    let span = b.frame.saturating_sub(a.frame).max(1) as f32;
    let t = (frame.saturating_sub(a.frame) as f32 / span).clamp(0.0, 1.0);
    let lerp = |p: f32, q: f32| p + t * (q - p);
    let w = libm::roundf(lerp(a.w as f32, b.w as f32)) as u32;
    let h = libm::roundf(lerp(a.h as f32, b.h as f32)) as u32;
    box_at(
        lerp(a.cx, b.cx) + lerp(a.dx, b.dx),
        lerp(a.cy, b.cy) + lerp(a.dy, b.dy),
        w,
        h,
    )
}

/// Reports a lost frame of `track`.
fn emit_lost(track: u32, frame: u32, bbox: Roi, sink: &mut impl FnMut(&PipelineEvent)) {
    sink(&PipelineEvent::TrackFrame {
        track,
        frame,
        obs: None,
        bbox,
        centre: None,
    });
}

/// Reports the lost frames `acc` holds: interpolated towards `next` (the
/// observation that ends the gap), or, without one, the predicted boxes.
fn flush_pending<const F: usize>(
    track: u32,
    acc: &mut TrackAcc<F>,
    next: Option<&LastObs>,
    sink: &mut impl FnMut(&PipelineEvent),
) {
    for p in acc.pending.iter() {
        let bbox = match (acc.last.as_ref(), next) {
            (Some(a), Some(b)) if a.frame < p.frame && p.frame < b.frame => {
                interpolated_box(a, b, p.frame)
            }
            (last, _) => predicted_box(last, p.x, p.y),
        };
        emit_lost(track, p.frame, bbox, sink);
    }
    acc.pending.clear();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::PathStep;

    #[test]
    fn default_pipeline_fits_512_kib() {
        let n = core::mem::size_of::<DefaultPipeline>();
        std::println!("size_of::<DefaultPipeline>() = {n}");
        assert!(n <= 512 * 1024, "{n}");
    }

    /// Replays track events through `handle` with an 8-frame history in
    /// which every frame holds `boxes[frame]` as observation 0.
    fn replay(
        events: &[TrackEvent<'_>],
        boxes: &[(u32, Roi)],
    ) -> std::vec::Vec<(u32, Option<u16>, Roi)> {
        let mut history: [FrameSlot<2>; 8] = core::array::from_fn(|_| FrameSlot {
            frame: None,
            obs: heapless::Vec::new(),
        });
        for &(f, b) in boxes {
            let slot = &mut history[f as usize % 8];
            slot.frame = Some(f);
            slot.obs.clear();
            let info = ObsInfo {
                bbox: b,
                cx: b.x as f32 + b.w as f32 / 2.0,
                cy: b.y as f32 + b.h as f32 / 2.0,
                ..ObsInfo::default()
            };
            slot.obs.push(info).unwrap();
        }
        let mut accs: heapless::Vec<TrackAcc<4>, 2> = heapless::Vec::new();
        let mut stats = PipelineStats::default();
        let mut out = std::vec::Vec::new();
        for e in events {
            handle(
                e,
                &history,
                &mut accs,
                &mut stats,
                0.25,
                &mut |pe: &PipelineEvent| {
                    if let PipelineEvent::TrackFrame {
                        frame, obs, bbox, ..
                    } = *pe
                    {
                        out.push((frame, obs, bbox));
                    }
                },
            );
        }
        out
    }

    fn step(frame: u32, obs: Option<u16>, x: i16, y: i16) -> TrackEvent<'static> {
        TrackEvent::Frame {
            track: 3,
            step: PathStep {
                frame,
                obs,
                pair: 0,
                x,
                y,
            },
        }
    }

    #[test]
    fn lost_frames_get_boxes_interpolated_between_observations() {
        // observed at frames 1 and 4, lost at 2 and 3 (predicted far off)
        let a = Roi::new(100, 100, 50, 20);
        let b = Roi::new(400, 160, 80, 20);
        let ev = [
            step(1, Some(0), 125, 110),
            step(2, None, 900, 900),
            step(3, None, 1000, 1000),
            step(4, Some(0), 440, 170),
        ];
        let out = replay(&ev, &[(1, a), (4, b)]);
        let frames: std::vec::Vec<u32> = out.iter().map(|r| r.0).collect();
        assert_eq!(
            frames,
            [1, 2, 3, 4],
            "lost frames reported in order, before the observation"
        );
        assert_eq!(out[0], (1, Some(0), a));
        assert_eq!(out[3], (4, Some(0), b));
        // centroids 125,110 -> 440,170; widths 50 -> 80
        assert_eq!(out[1], (2, None, Roi::new(200, 120, 60, 20)));
        assert_eq!(out[2], (3, None, Roi::new(300, 140, 70, 20)));
    }

    #[test]
    fn lost_frames_without_a_later_observation_keep_the_predicted_box() {
        let a = Roi::new(100, 100, 50, 20);
        let ev = [
            step(1, Some(0), 125, 110),
            step(2, None, 325, 210),
            TrackEvent::Closed {
                track: 3,
                reason: CloseReason::End,
                first_frame: 1,
                last_frame: 1,
                hits: 1,
                path: &[],
                truncated: false,
            },
        ];
        let out = replay(&ev, &[(1, a)]);
        // the last box moved to the prediction, reported at the close
        assert_eq!(
            out,
            [(1, Some(0), a), (2, None, Roi::new(300, 200, 50, 20))]
        );
        // more lost frames than MAX_PENDING: the oldest go out predicted.
        // The fish moves 10 px a frame; the predictions are 500 px ahead.
        let mut ev = std::vec![step(1, Some(0), 125, 110)];
        for f in 2..(MAX_PENDING as u32 + 4) {
            ev.push(step(f, None, 615 + 10 * f as i16, 110));
        }
        let end = MAX_PENDING as u32 + 4;
        ev.push(step(end, Some(0), 115 + 10 * end as i16, 110));
        let b = Roi::new(90 + 10 * end, 100, 50, 20);
        let out = replay(&ev, &[(1, a), (end, b)]);
        assert_eq!(out.len(), end as usize);
        assert!(out.windows(2).all(|w| w[0].0 < w[1].0), "frames in order");
        for (f, _, bx) in &out[1..out.len() - 1] {
            // frames 2 and 3 overflowed the buffer: the predicted box;
            // the rest waited for frame `end`: on the line between
            let want = if *f <= 3 { 590 } else { 90 } + 10 * f;
            assert_eq!(bx.x, want, "frame {f}");
        }
    }

    #[test]
    fn history_must_be_deeper_than_trellis() {
        let geom = StereoGeometry {
            f: 1000.0,
            cx: 256.0,
            cy: 256.0,
            cx_right: 256.0,
            baseline_mm: 100.0,
        };
        let cfg = PipelineConfig::new(Params::for_frame(512), geom, 512, 512);
        assert_eq!(
            Pipeline::<4, 64, 4, 8, 4, 8, 8, 8>::new(cfg).err(),
            Some(PipelineError::History)
        );
        assert!(Pipeline::<4, 64, 4, 8, 4, 8, 9, 8>::new(cfg).is_ok());
    }
}
