//! `truth.json`: the ground truth of a synthetic haul, written by
//! `fishtrack synth` and read by `fishtrack eval`.
//!
//! Coordinates: boxes are `[x, y, w, h]` in **raw** (distorted, unrectified)
//! image pixels, x to the right, y down, pixel centres at integer + 0.5
//! (box `[0, 0, 1, 1]` is the first pixel). 3-D points are millimetres in
//! the left camera frame (OpenCV convention: x right, y down, z forward).
//! Frames are numbered from 1, as in `tracks.csv`.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::InputError;

/// Schema version written in `truth.json`.
pub const TRUTH_VERSION: u32 = 1;

/// The whole ground truth of a haul.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Schema version ([`TRUTH_VERSION`]).
    pub version: u32,
    /// Generator seed.
    pub seed: u64,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// Frames per second.
    pub fps: f64,
    /// Number of stereo frame pairs; frame files are `left/NNNNNN.png` for 1..=frames.
    pub frames: u32,
    /// Every fish that is visible in at least one frame of either view.
    pub fish: Vec<TruthFish>,
}

/// One fish.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthFish {
    /// Unique id, from 1.
    pub id: u32,
    /// True 3-D body length, snout to tail tip, mm.
    pub length_mm: f64,
    /// Reflectivity of the caudal fin relative to the body (1 = same; the
    /// paper's "less reflective" tails are well below 1).
    pub tail_reflectivity: f64,
    /// The frames where the fish is at least partly visible in one view, in order.
    pub frames: Vec<TruthFrame>,
}

/// A fish in one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthFrame {
    /// Frame number, from 1.
    pub frame: u32,
    /// Upright box of the visible fish in the raw left image, `[x, y, w, h]`; `None` if not visible there.
    pub left_box: Option<[f64; 4]>,
    /// Upright box of the visible fish in the raw right image; `None` if not visible there.
    pub right_box: Option<[f64; 4]>,
    /// Visible (unoccluded, inside the frame) area in the left image, pixels.
    pub left_area: f64,
    /// Visible area in the right image, pixels.
    pub right_area: f64,
    /// Visible fraction of the whole body's silhouette in the left image, `[0, 1]`.
    pub left_visible_fraction: f64,
    /// Visible fraction in the right image.
    pub right_visible_fraction: f64,
    /// True when the whole fish (head to tail tip) lies inside the left image.
    pub inside_left: bool,
    /// True when the whole fish lies inside the right image.
    pub inside_right: bool,
    /// Snout point, mm, left camera frame.
    pub head_mm: [f64; 3],
    /// Tail-tip point, mm, left camera frame.
    pub tail_mm: [f64; 3],
    /// Snout point projected into the raw (distorted) left image, pixels;
    /// optional (`eval` uses it for the single-camera pixel length).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_px_left: Option<[f64; 2]>,
    /// Tail-tip point projected into the raw left image, pixels; optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tail_px_left: Option<[f64; 2]>,
}

impl Truth {
    /// Reads and checks `truth.json`.
    pub fn load(path: &Path) -> Result<Truth, InputError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
        let t: Truth = serde_json::from_str(&text)
            .map_err(|e| InputError::file(path, format!("not a valid truth.json: {e}")))?;
        if t.version != TRUTH_VERSION {
            return Err(InputError::key(
                path,
                "version",
                format!(
                    "schema version {} is not supported (expected {TRUTH_VERSION})",
                    t.version
                ),
            ));
        }
        Ok(t)
    }
}
