//! Frames for the pipeline, decoded and rectified ahead of the core (paper
//! Fig. 6: frame capture and rectification feed segmentation).
//!
//! [`for_each_rectified`] runs a producer thread that reads and rectifies
//! the haul's pairs in order (left and right side by side on the rayon
//! pool, each remap split into row bands), and hands them through a
//! bounded queue of [`QUEUE_DEPTH`] pairs to the caller's closure, which
//! runs on the calling thread (the core's one thread). So decoding and
//! rectification overlap the core's work, memory stays bounded (at most
//! `QUEUE_DEPTH + 2` rectified pairs alive), and frames are processed in
//! order. Errors keep naming the file and frame: a producer error stops the
//! run and is returned; a consumer error stops the producer.

use std::sync::mpsc::sync_channel;
use std::time::Instant;

use anyhow::Result;
use image::GrayImage;

use crate::error::InputError;
use crate::haul::FramePair;
use crate::track_cmd::Setup;

/// Rectified pairs the producer may run ahead of the core.
pub const QUEUE_DEPTH: usize = 2;

/// One rectified pair and what it cost to make.
pub struct RectifiedPair<'a> {
    /// The haul's pair.
    pub pair: &'a FramePair,
    /// Rectified left frame.
    pub left: GrayImage,
    /// Rectified right frame.
    pub right: GrayImage,
    /// Seconds spent reading and decoding both files.
    pub read_s: f64,
    /// Seconds spent rectifying both frames.
    pub rectify_s: f64,
}

/// Reads and rectifies one pair (both sides in parallel).
pub fn rectify_one<'a>(setup: &Setup, pair: &'a FramePair) -> Result<RectifiedPair<'a>> {
    let t0 = Instant::now();
    let (l, r) = setup.load_pair(pair)?;
    let read_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (left, right) = setup.rectifier.rectify_pair(&l, &r).map_err(|e| {
        InputError::file(
            &pair.left,
            format!("frame {}: cannot rectify: {e:?}", pair.index),
        )
    })?;
    Ok(RectifiedPair {
        pair,
        left,
        right,
        read_s,
        rectify_s: t1.elapsed().as_secs_f64(),
    })
}

/// Calls `f` on every rectified pair of `pairs`, in order, with reading
/// and rectification running ahead on another thread (see the module doc).
pub fn for_each_rectified<'a>(
    setup: &Setup,
    pairs: &'a [FramePair],
    mut f: impl FnMut(RectifiedPair<'a>) -> Result<()>,
) -> Result<()> {
    let (tx, rx) = sync_channel::<Result<RectifiedPair<'a>>>(QUEUE_DEPTH);
    // `move`: the receiver is dropped when the closure returns, before the
    // scope joins the producer, so a consumer error never leaves it blocked
    std::thread::scope(move |s| {
        s.spawn(move || {
            for pair in pairs {
                let item = rectify_one(setup, pair);
                let stop = item.is_err();
                // the receiver is gone when the consumer failed: stop
                if tx.send(item).is_err() || stop {
                    break;
                }
            }
        });
        for item in rx.iter() {
            f(item?)?;
        }
        Ok(())
    })
}
