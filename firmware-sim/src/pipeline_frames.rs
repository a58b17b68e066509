//! The core vision pipeline ([`fishtrack_core::pipeline`], paper Fig. 6)
//! hooked into the simulated device: each triggered frame reads the next
//! stereo pair of the haul, rectifies it (host side, as the camera
//! front-end would), runs segmentation → stereo pairing → length →
//! tracking, and reports the frame's left objects, the live tracks and
//! every fish whose track closed, with its length. After the last frame of
//! the haul the remaining tracks are flushed ([`Pipeline::finish`]).
//!
//! Fish are the closed tracks that are not duplicates, exactly as
//! `fishtrack track` writes them to `fish.csv` (one core, two hosts); a fish
//! without a measurable frame reports length −1.
//!
//! [`Pipeline::finish`]: fishtrack_core::pipeline::Pipeline::finish

use fishtrack::track_cmd::{new_pipeline, prepare, views, Setup, TrackOptions};
use fishtrack_core::link::{FishClosed, FrameReport};
use fishtrack_core::pipeline::{DefaultPipeline, PipelineEvent};
use fishtrack_core::track::CloseReason;

use crate::device::{FrameOutcome, FrameProcessor};

/// A haul run through the core pipeline, one frame per trigger.
pub struct PipelineFrames {
    setup: Setup,
    pipe: Box<DefaultPipeline>,
    ws: Vec<u8>,
    done: bool,
}

impl PipelineFrames {
    /// Opens the haul and prepares calibration, rectification and the pipeline.
    pub fn open(dir: &std::path::Path) -> anyhow::Result<Self> {
        let setup = prepare(dir, &TrackOptions::default())?;
        let pipe = new_pipeline(&setup)?;
        let ws =
            vec![0u8; DefaultPipeline::workspace_size(setup.width as usize, setup.height as usize)];
        Ok(PipelineFrames {
            setup,
            pipe,
            ws,
            done: false,
        })
    }

    /// Number of frame pairs in the haul.
    pub fn len(&self) -> u32 {
        self.setup.haul.frames.len() as u32
    }

    /// The haul directory.
    pub fn dir(&self) -> &std::path::Path {
        &self.setup.haul.dir
    }
}

/// Every closed track that is neither a duplicate nor an unconfirmed
/// tentative target is a fish. (`fishtrack track`, which knows the raw
/// view, also drops a track whose boxes all lie in the fill of an
/// `alpha > 0` rectification, and one whose every observed box inside the
/// raw view is smaller than θ_A^L; the device cannot tell, so on a haul
/// with such a track the two counts differ by it.)
fn fish_of(e: &PipelineEvent, out: &mut Vec<FishClosed>) {
    if let PipelineEvent::TrackClosed {
        track,
        reason,
        first_frame,
        last_frame,
        length,
        ..
    } = *e
    {
        if !matches!(reason, CloseReason::Duplicate | CloseReason::Unconfirmed) {
            out.push(FishClosed {
                track_id: track,
                first_frame,
                last_frame,
                length_mm: length.median_mm.unwrap_or(-1.0),
            });
        }
    }
}

impl FrameProcessor for PipelineFrames {
    fn process_frame(&mut self, index: u32) -> Option<FrameOutcome> {
        if self.done {
            return None;
        }
        let pair = self.setup.haul.frames.get(index as usize)?.clone();
        let (l, r) = match self.setup.rectified(&pair) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("fishtrack-firmware-sim: {e:#}");
                return None;
            }
        };
        let (lv, rv) = views(&l, &r).ok()?;
        let mut closed = Vec::new();
        let mut report = FrameReport {
            frame: index,
            objects: 0,
            tracks: 0,
        };
        let res = self
            .pipe
            .process_frame(pair.index, lv, rv, &mut self.ws, &mut |e| {
                fish_of(e, &mut closed);
                if let PipelineEvent::FrameDone { counts, .. } = e {
                    report.objects = counts.left_objects.min(u16::MAX as u32) as u16;
                    report.tracks = counts.live_tracks.min(u16::MAX as u32) as u16;
                }
            });
        if let Err(e) = res {
            eprintln!("fishtrack-firmware-sim: frame {}: {e}", pair.index);
            return None;
        }
        if index as usize + 1 == self.setup.haul.frames.len() {
            self.pipe.finish(&mut |e| fish_of(e, &mut closed));
            self.done = true;
        }
        Some(FrameOutcome { report, closed })
    }
}
